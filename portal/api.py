"""The JSON API under /api/ (django-ninja): typed schemas give the OpenAPI document at /api/openapi.json.

Every route needs a logged-in session (401 otherwise); permissions are checked per route (403).
"""

from functools import wraps

from django.http import JsonResponse
from ninja import NinjaAPI
from ninja.security import django_auth


def login_required_401(view):
    """Like login_required, but an API answers 401 instead of redirecting to a form."""

    @wraps(view)
    def wrapper(request, *args, **kwargs):
        if not request.user.is_authenticated:
            return JsonResponse({"detail": "Unauthorized"}, status=401)
        return view(request, *args, **kwargs)

    return wrapper


api = NinjaAPI(
    title="Fleet portal API",
    version="1",
    auth=django_auth,
    urls_namespace="api",
    docs_url="/docs",
    docs_decorator=login_required_401,
)


def _mount_routers():
    from portal.api_alerts import router as alerts_router
    from portal.api_interpreter import router as interpreter_router
    from portal.api_robots import router as robots_router
    from portal.api_routes import router as fleet_router

    api.add_router("/", fleet_router)
    api.add_router("/robots", robots_router)
    api.add_router("/interpreter", interpreter_router)
    api.add_router("/alerts", alerts_router)


_mount_routers()
