"""ASGI entry point: HTTP through Django, WebSockets through Channels (authenticated by the session)."""

import gc
import os

from django.core.asgi import get_asgi_application

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")
django_http = get_asgi_application()  # sets Django up before the consumers import models

from channels.auth import AuthMiddlewareStack  # noqa: E402
from channels.routing import ProtocolTypeRouter, URLRouter  # noqa: E402
from channels.security.websocket import AllowedHostsOriginValidator  # noqa: E402

from fleet.routing import websocket_urlpatterns  # noqa: E402
from fleetcore import heartbeat  # noqa: E402

router = ProtocolTypeRouter(
    {
        "http": django_http,
        "websocket": AllowedHostsOriginValidator(AuthMiddlewareStack(URLRouter(websocket_urlpatterns))),
    }
)


async def application(scope, receive, send):
    """The router, and the server's lifespan: the heartbeat runs on the event loop while it serves."""
    if scope["type"] == "lifespan":
        return await lifespan(receive, send)
    return await router(scope, receive, send)


async def lifespan(receive, send) -> None:
    """ASGI lifespan: beat from the serving loop (a blocked loop stops the beats; fleet/hangwatch.py)."""
    beat, task = heartbeat.from_env(), None
    while True:
        message = await receive()
        if message["type"] == "lifespan.startup":
            task = beat.start_task() if beat else None
            await send({"type": "lifespan.startup.complete"})
        elif message["type"] == "lifespan.shutdown":
            if task is not None:
                task.cancel()
            await send({"type": "lifespan.shutdown.complete"})
            return


# Everything loaded so far (Django, the app registry, the URL conf) lives as long as the process: keep it out
# of the collector's scans, so a full collection pauses the event loop for milliseconds, not ~50 ms.
gc.freeze()
