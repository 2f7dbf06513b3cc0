"""The JSON API under /api/ (django-ninja): typed schemas give the OpenAPI document at /api/openapi.json.

Every operation names the ability it needs (access.roles.ABILITIES): anonymous callers get 401, a role without
the ability 403, both before the body is read. Reads need "view" (the default below). Bad input gets a 4xx
whose detail names the field; nothing a caller sends may end in a 500.
"""

from functools import wraps

from django.http import JsonResponse
from ninja import NinjaAPI
from ninja.errors import HttpError
from ninja.openapi.docs import Swagger
from ninja.renderers import JSONRenderer

from access.roles import api_auth, may, refusal
from portal.api_alerts import router as alerts_router
from portal.api_interpreter import router as interpreter_router
from portal.api_robots import router as robots_router
from portal.api_routes import router as fleet_router
from portal.api_tasklist import router as tasklist_router

UNPARSEABLE = "Cannot parse request body"


def view_required(view):
    """The docs and the schema: 401 for anonymous callers, 403 without the "view" ability (no redirect)."""

    @wraps(view)
    def wrapper(request, *args, **kwargs):
        if not request.user.is_authenticated:
            return JsonResponse({"detail": "Unauthorized"}, status=401)
        if not may(request.user, "view"):
            return JsonResponse({"detail": refusal(request.user, "view")}, status=403)
        return view(request, *args, **kwargs)

    wrapper.abilities = {"GET": "view", "HEAD": "view"}
    return wrapper


class StrictJSONRenderer(JSONRenderer):
    """Strict JSON: a NaN or an infinity in an answer is an error here, never a bare NaN a client cannot parse."""

    json_dumps_params = {"allow_nan": False}


api = NinjaAPI(
    renderer=StrictJSONRenderer(),
    title="Fleet portal API",
    version="1",
    auth=api_auth("view"),
    urls_namespace="api",
    docs_url="/docs",
    # Swagger UI from ninja's bundled static files (ninja is an installed app); no validator badge, which would
    # send the schema's address to validator.swagger.io
    docs=Swagger(settings={"validatorUrl": None}),
    docs_decorator=view_required,
)


@api.exception_handler(HttpError)
def http_error(request, exc: HttpError):
    """ninja's own 400 for a body that is not JSON names no field: say it is the body."""
    detail = str(exc)
    if exc.status_code == 400 and detail.startswith(UNPARSEABLE):
        detail = "body: not a JSON document this operation accepts"
    return api.create_response(request, {"detail": detail}, status=exc.status_code)


def _mount_routers():
    api.add_router("/", fleet_router)
    api.add_router("/", tasklist_router)
    api.add_router("/robots", robots_router)
    api.add_router("/interpreter", interpreter_router)
    api.add_router("/alerts", alerts_router)


_mount_routers()
