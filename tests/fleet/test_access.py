"""Every page, API route and WebSocket needs a login; each role can do what it should and no more."""

import re

import pytest
from django.urls import URLPattern, URLResolver, get_resolver

# Sample values for URL parameters, so that every route can be requested.
SAMPLE_ARGS = {
    "int": "1",
    "str": "x",
    "slug": "x",
    "path": "x",
    "uuid": "00000000-0000-0000-0000-000000000000",
}


def _walk(patterns, prefix=""):
    for entry in patterns:
        if isinstance(entry, URLResolver):
            yield from _walk(entry.url_patterns, prefix + str(entry.pattern))
        elif isinstance(entry, URLPattern):
            yield prefix + str(entry.pattern)


def _concrete(route: str) -> str:
    """Turn a route pattern into a path a client can request."""
    route = re.sub(r"<(?:(\w+):)?\w+>", lambda m: SAMPLE_ARGS.get(m.group(1) or "str", "x"), route)
    route = route.lstrip("^").rstrip("$").replace("\\Z", "").replace("\\", "")
    route = re.sub(r"\(\?P<\w+>[^)]*\)", "x", route)
    return "/" + route


ALL_PATHS = sorted({_concrete(route) for route in _walk(get_resolver().url_patterns)})
OPEN_PATHS = {"/login/", "/admin/login/"}  # the login forms themselves, and nothing else


def test_url_conf_was_enumerated():
    assert "/api/robots" in ALL_PATHS
    assert "/admin/" in ALL_PATHS
    assert len(ALL_PATHS) > 20
    assert set(ALL_PATHS) >= OPEN_PATHS  # the open ones are real pages, not stale names


@pytest.mark.django_db
@pytest.mark.parametrize("path", [path for path in ALL_PATHS if path not in OPEN_PATHS])
def test_anonymous_gets_no_content_anywhere(client, path):
    for method in (client.get, client.post):
        response = method(path)
        if path.startswith("/api/"):
            assert response.status_code in {401, 403, 404, 405}, (path, response.status_code)
            assert response.status_code != 200
        else:
            assert response.status_code in {301, 302, 404, 405}, (path, response.status_code)
            if response.status_code == 302:
                assert "/login/" in response["Location"], (path, response["Location"])


@pytest.mark.django_db
def test_anonymous_root_leads_to_login_form(client):
    response = client.get("/", follow=True)
    assert response.redirect_chain[-1][0].startswith("/login/")
    assert b'name="password"' in response.content


@pytest.mark.django_db
def test_anonymous_api_robots_is_401(client):
    assert client.get("/api/robots").status_code == 401


@pytest.mark.django_db
def test_openapi_schema_needs_no_guessing(client_for, viewer):
    schema = client_for(viewer).get("/api/openapi.json").json()
    assert "/api/robots" in schema["paths"]
    assert "/api/instructions" in schema["paths"]


@pytest.mark.django_db
def test_viewer_sees_but_cannot_instruct(client_for, viewer):
    client = client_for(viewer)
    assert client.get("/").status_code == 200
    assert client.get("/api/robots").status_code == 200
    response = client.post("/api/instructions", {"text": "stop"}, content_type="application/json")
    assert response.status_code == 403
    assert "may not give instructions" in response.json()["detail"]


@pytest.mark.django_db
def test_operator_cannot_edit_schedules(client_for, operator):
    response = client_for(operator).post(
        "/api/schedules",
        {"robot": "husky", "start": "09:00", "end": "10:00", "goal": "A"},
        content_type="application/json",
    )
    assert response.status_code == 403


@pytest.mark.django_db
def test_bad_schedule_input_names_the_field(client_for, fleet_admin):
    client = client_for(fleet_admin)
    response = client.post(
        "/api/schedules",
        {"robot": "nobody", "start": "09:00", "end": "10:00", "goal": "A"},
        content_type="application/json",
    )
    assert response.status_code == 422
    assert "robot" in response.json()["detail"]
    response = client.post("/api/schedules", {"robot": "x", "start": "nine"}, content_type="application/json")
    assert response.status_code == 422
    assert "start" in str(response.json()["detail"])


@pytest.mark.django_db
def test_every_admin_page_renders_for_an_admin(client_for, fleet_admin):
    from django.contrib import admin

    client = client_for(fleet_admin)
    assert client.get("/admin/").status_code == 200
    for model in admin.site._registry:
        meta = model._meta
        for suffix in ("", "add/"):
            path = f"/admin/{meta.app_label}/{meta.model_name}/{suffix}"
            status = client.get(path).status_code
            assert status in {200, 403}, (path, status)  # 403: append-only models refuse add


@pytest.mark.django_db
def test_viewer_cannot_open_the_admin(client_for, viewer):
    assert client_for(viewer).get("/admin/").status_code == 302
