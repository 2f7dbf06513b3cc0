"""Login everywhere (pages redirect to the login form, the API answers 401 itself), a Content-Security-Policy on
every answer, and a store that refuses said as a 503 with its reason rather than a bare 500."""

from __future__ import annotations

import logging
import sys
import threading
import time

from django.conf import settings
from django.contrib.auth.middleware import LoginRequiredMiddleware
from django.db import connection
from django.http import HttpResponse, JsonResponse
from django.utils.html import escape
from django.views.defaults import server_error as plain

import alerts
from fleetcore import faults

log = logging.getLogger(__name__)
ALERT_EVERY_S = 30.0  # one alert per reason and process this often at most: a failing store is not hammered
_alerted: dict[str, float] = {}


class LoginRequired(LoginRequiredMiddleware):
    """Django's LoginRequiredMiddleware, except for /api/, whose own auth answers 401 (not a redirect)."""

    def process_view(self, request, view_func, view_args, view_kwargs):
        if request.path_info.startswith("/api/"):
            return None
        return super().process_view(request, view_func, view_args, view_kwargs)


class ContentSecurityPolicy:
    """Send settings.SECURE_CSP (Django 6's setting, so its own middleware can take over) on every answer that has
    none: scripts and styles only from our own files, no inline code, nothing framed. Django 5.2 has no CSP."""

    def __init__(self, get_response) -> None:
        self.get_response = get_response
        self.header = "; ".join(
            f"{directive} {' '.join(sources)}".strip() for directive, sources in settings.SECURE_CSP.items()
        )

    def __call__(self, request):
        response = self.get_response(request)
        response.headers.setdefault("Content-Security-Policy", self.header)
        return response


class StoreRefusals:
    """A view that failed because Redis or the database is away or refuses writes (a full disk, a lock) answers
    503 with the reason, and an alert is raised when the database can take it."""

    def __init__(self, get_response) -> None:
        self.get_response = get_response

    def __call__(self, request):
        return self.get_response(request)

    def process_exception(self, request, exception):
        return unavailable(request, exception)


def unavailable(request, exception) -> HttpResponse | None:
    """The 503 for a store's failure (None for any other exception): JSON for the API and fetch(), else a page."""
    words = faults.store_fault(exception)
    if words is None:
        return None
    log.error("%s %s: 503, %s (%r)", request.method, request.path, words, exception)
    _alert(words)
    detail = f"Service unavailable: {words}. Robots can still be stopped."
    wants_json = (
        "application/json" in request.headers.get("Accept", "") or request.content_type == "application/json"
    )
    if request.path_info.startswith("/api/") or wants_json:
        return JsonResponse({"detail": detail}, status=503)
    return HttpResponse(f"<!doctype html><title>503</title><h1>503</h1><p>{escape(detail)}</p>", status=503)


def server_error(request, *args, **kwargs):
    """handler500: a store's failure raised outside a view (a middleware, the session) is a 503 too."""
    exception = sys.exc_info()[1]
    answer = unavailable(request, exception) if exception is not None else None
    if answer is not None:
        return answer
    return plain(request, *args, **kwargs)


def _alert(words: str) -> None:
    """Raise the store_refused alert in a thread of its own (a locked database must not hold the answer)."""
    now = time.monotonic()
    if now - _alerted.get(words, float("-inf")) < ALERT_EVERY_S:
        return
    _alerted[words] = now
    threading.Thread(target=_raise_alert, args=(words,), name="store alert", daemon=True).start()


def _raise_alert(words: str) -> None:
    try:
        alerts.raise_alert("store_refused", None, f"{words} (pages answer 503)")
    finally:
        connection.close()
