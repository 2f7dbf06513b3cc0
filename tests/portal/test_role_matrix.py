"""Every way in, checked against the role matrix (access.roles.ABILITIES) for anonymous, viewer, operator, admin.

Every URL pattern of the project, every operation of the OpenAPI document and every socket message type: each
declares the ability it needs (a page's @requires mark, an operation's ``may_<ability>`` security scheme, a socket
command's COMMANDS entry), a way in that declares none fails here, and each is called as each role: anonymous
callers are sent to the login (pages), get 401 (API) or a 4401 close (sockets); a role without the ability gets
403 or a refusal in words; a role with it gets through (whatever the call then says about its input).
"""

import re

import pytest
from asgiref.sync import sync_to_async
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import Group, User
from django.urls import URLPattern, URLResolver, get_resolver

from access.roles import ABILITIES, ADMIN, OPERATOR, ROLES, VIEWER, sync_groups

CALLERS = (None, VIEWER, OPERATOR, ADMIN)  # None: anonymous
PUBLIC = {"login", "logout", "api-root"}  # the only ways in without a session (api-root: always 404)


def allowed(role: str | None, ability: str) -> bool:
    """What the matrix says: the role has the ability."""
    return role is not None and role in ABILITIES[ability].roles()


# --- the world the calls land in ----------------------------------------------------------------------------


@pytest.fixture
def members(db):
    """One user per role, holding only their group (the admin is staff but no superuser: no bypass)."""
    sync_groups()
    users = {}
    for role in ROLES:
        user = User.objects.create_user(f"{role}-user", password="x" * 12, is_staff=role == ADMIN)
        user.groups.add(Group.objects.get(name=role))
        users[role] = user
    return users


def test_the_readme_shows_the_matrix_as_it_is():
    from pathlib import Path

    from access.roles import matrix_markdown

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    assert matrix_markdown() in readme


# --- URL patterns ---------------------------------------------------------------------------------------------


def _patterns(resolvers=None, prefix=""):
    """(route, pattern) for every URL pattern of the project, includes walked."""
    for entry in resolvers if resolvers is not None else get_resolver().url_patterns:
        route = prefix + str(entry.pattern)
        if isinstance(entry, URLResolver):
            yield from _patterns(entry.url_patterns, route)
        elif isinstance(entry, URLPattern):
            yield route, entry


def _page_patterns():
    return [(r, p) for r, p in _patterns() if not r.startswith(("admin/", "api/")) and p.name not in PUBLIC]


def test_every_url_pattern_declares_who_may_use_it():
    """Pages carry @requires marks; the API's patterns are its operations (below) and its docs; admin is Django's."""
    from portal.api import api

    schema_paths = set(api.get_openapi_schema()["paths"])
    undeclared = []
    for route, pattern in _patterns():
        if route.startswith("admin/") or pattern.name in PUBLIC:
            continue
        if route.startswith("api/"):
            as_path = "/" + re.sub(r"<(?:\w+:)?(\w+)>", r"{\1}", route)
            if as_path in schema_paths or getattr(pattern.callback, "abilities", None):
                continue
        elif getattr(pattern.callback, "abilities", None):
            continue
        undeclared.append(route)
    assert undeclared == []


@pytest.mark.parametrize("role", CALLERS, ids=lambda role: role or "anonymous")
def test_the_api_docs_and_schema_answer_each_role_as_the_matrix_says(client, members, role):
    if role is not None:
        client.force_login(members[role])
    docs = [(r, p) for r, p in _patterns() if r.startswith("api/") and getattr(p.callback, "abilities", None)]
    assert {p.name for _, p in docs} == {"openapi-json", "openapi-view"}
    for route, pattern in docs:
        response = client.get("/" + route)
        ability = pattern.callback.abilities["GET"]
        expected = 401 if role is None else 200 if allowed(role, ability) else 403
        assert response.status_code == expected, route


def test_the_api_root_answers_nothing_but_404(client):
    assert client.get("/api/").status_code == 404


def _url(route: str, world) -> str:
    kwargs = {"pk": world["binding"].pk if route.startswith("register/bindings/") else world["robot"].pk}
    return "/" + re.sub(r"<(?:\w+:)?(\w+)>", lambda m: str(kwargs[m.group(1)]), route)


@pytest.mark.parametrize("role", CALLERS, ids=lambda role: role or "anonymous")
def test_every_page_answers_each_role_as_the_matrix_says(client, members, world, recorded_control, role):
    if role is not None:
        client.force_login(members[role])
    checked = 0
    for route, pattern in _page_patterns():
        for method, ability in pattern.callback.abilities.items():
            if method == "HEAD":
                continue
            url = _url(route, world)
            response = client.generic(method, url, "", content_type="application/x-www-form-urlencoded")
            where = f"{method} {url} as {role or 'anonymous'} (needs {ability})"
            if role is None:
                assert response.status_code == 302 and response["Location"].startswith("/login/"), where
            elif allowed(role, ability):
                assert response.status_code not in {401, 403}, where
                assert not response.get("Location", "").startswith("/login/"), where
            else:
                assert response.status_code == 403, where
            checked += 1
    assert checked >= 13  # every page and action of portal.urls, GET and POST


@pytest.mark.parametrize("role", CALLERS, ids=lambda role: role or "anonymous")
def test_the_admin_site_is_for_staff_and_shows_what_their_permissions_allow(client, members, role):
    """Anonymous callers and the roles that are not staff are sent to the admin's login; the admin user gets
    each model's list if the matrix's groups give them its view permission, 403 otherwise."""
    from django.contrib import admin

    if role is not None:
        client.force_login(members[role])
    for model, model_admin in admin.site._registry.items():
        url = f"/admin/{model._meta.app_label}/{model._meta.model_name}/"
        response = client.get(url)
        if role != ADMIN:  # the portal's login for anonymous callers, the admin's for non-staff users
            assert response.status_code == 302 and "login/" in response["Location"], url
            continue
        expected = 200 if model_admin.has_view_or_change_permission(_request_for(members[role])) else 403
        assert response.status_code == expected, url


def _request_for(user):
    from django.test import RequestFactory

    request = RequestFactory().get("/admin/")
    request.user = user
    return request


def test_nobody_adds_changes_or_deletes_audit_entries_in_the_admin(client, members):
    from audit import records as audit

    entry = audit.record(members[ADMIN], "test.entry", "something")
    superuser = User.objects.create_superuser("root", password="x" * 12)
    client.force_login(superuser)
    assert client.get("/admin/audit/auditentry/").status_code == 200
    assert client.get("/admin/audit/auditentry/add/").status_code == 403
    assert client.post(f"/admin/audit/auditentry/{entry.pk}/delete/", {"post": "yes"}).status_code == 403
    client.post(f"/admin/audit/auditentry/{entry.pk}/change/", {"action": "rewritten"})
    entry.refresh_from_db()
    assert entry.action == "test.entry"


# --- API operations -------------------------------------------------------------------------------------------


def _operations():
    """(method, path, ability) for every operation of the OpenAPI document."""
    from portal.api import api

    schema = api.get_openapi_schema()
    for path, methods in schema["paths"].items():
        for method, operation in methods.items():
            (scheme,) = (name for requirement in operation["security"] for name in requirement)
            assert scheme.startswith("may_"), f"{method} {path}: no ability in its security scheme"
            yield method.upper(), path, scheme.removeprefix("may_")


def test_every_api_operation_names_an_ability_of_the_matrix():
    operations = list(_operations())
    assert len(operations) >= 14
    assert {ability for _, _, ability in operations} <= set(ABILITIES)


def _api_url(path: str, world) -> str:
    values = {
        "slot_id": world["slot"].pk,
        "instruction_id": 1,
        "record_id": 1,
        "name": world["robot"].name,
        "action": "odometry",
        "alert_id": 1,
    }
    return re.sub(r"{(\w+)}", lambda m: str(values[m.group(1)]), path)


@pytest.mark.parametrize("role", CALLERS, ids=lambda role: role or "anonymous")
def test_every_api_operation_answers_each_role_as_the_matrix_says(client, members, world, role):
    """With an empty body: the refused are refused before it is read, the allowed get past the role check
    (to a 422 for the missing fields, or the answer itself)."""
    if role is not None:
        client.force_login(members[role])
    for method, path, ability in _operations():
        url = _api_url(path, world)
        response = client.generic(
            method, url, "{}" if method != "GET" else "", content_type="application/json"
        )
        where = f"{method} {url} as {role or 'anonymous'} (needs {ability})"
        if role is None:
            assert response.status_code == 401, where
        elif allowed(role, ability):
            assert response.status_code not in {401, 403}, where
        else:
            assert response.status_code == 403, where
            assert f"({ability})" in response.json()["detail"], where


def test_a_viewer_cannot_teach_the_interpreter(client, members, world, seeded_words):
    """The attack of issue 15: "forget halt", then "halt means move", by a viewer."""
    from interpreter.models import Lesson, Synonym

    client.force_login(members[VIEWER])
    for answer in ("forget halt", "halt means move", "sea is a location at (3, 4)"):
        reply = client.post("/api/interpreter/teach", {"answer": answer}, content_type="application/json")
        assert reply.status_code == 403
    assert Synonym.objects.filter(word="halt").exists()
    assert not Lesson.objects.exists()
    assert not world["location"].map.locations.filter(name="sea").exists()


def test_an_operator_teaches_new_words_and_undoes_them_but_cannot_forget_seeded_ones(
    client, members, world, seeded_words
):
    from audit.models import AuditEntry
    from interpreter.models import Synonym

    client.force_login(members[OPERATOR])

    def teach(answer):
        return client.post("/api/interpreter/teach", {"answer": answer}, content_type="application/json")

    refused = teach("forget halt")
    assert refused.status_code == 403 and "edit_vocabulary" in refused.json()["detail"]
    assert Synonym.objects.filter(word="halt").exists()
    assert teach("halt means move").json()["ok"] is False  # a known word is never redefined
    assert teach("zoom means move").json()["ok"] is True
    assert Synonym.objects.get(word="zoom").action.name == "move"
    assert teach("forget zoom").json()["ok"] is True  # the undo of a lesson
    assert not Synonym.objects.filter(word="zoom").exists()
    taught = AuditEntry.objects.filter(action="ontology.teach", user=members[OPERATOR])
    assert sorted(taught.values_list("target", flat=True)) == ["zoom", "zoom"]


def test_an_admin_may_forget_a_seeded_word(client, members, world, seeded_words):
    from interpreter.models import Synonym

    client.force_login(members[ADMIN])
    reply = client.post("/api/interpreter/teach", {"answer": "forget halt"}, content_type="application/json")
    assert reply.status_code == 200 and reply.json()["ok"] is True
    assert not Synonym.objects.filter(word="halt").exists()


# --- socket message types -------------------------------------------------------------------------------------


@sync_to_async
def _session_cookie(user) -> bytes:
    from django.test import Client

    client = Client()
    client.force_login(user)
    return f"sessionid={client.cookies['sessionid'].value}".encode()


async def _socket(user):
    from fleet.asgi import application

    headers = [(b"origin", b"http://127.0.0.1")]
    if user is not None:
        headers.append((b"cookie", await _session_cookie(user)))
    communicator = WebsocketCommunicator(application, "/ws/fleet/", headers=headers)
    connected, _ = await communicator.connect()
    assert connected
    return communicator


def _message(command: str, robot_id: int) -> dict:
    """A well-formed message of each type the sockets accept."""
    examples = {
        "stop": {"command": "stop", "robots": [robot_id]},
        "teleop": {"command": "teleop", "robot": robot_id, "linear": 0.1, "angular": 0.0},
        "instruct": {"command": "instruct", "text": "flurble"},  # asked back (type V): nothing is dispatched
    }
    return {**examples[command], "ref": command}


@pytest.mark.django_db(transaction=True)
@pytest.mark.asyncio
@pytest.mark.timeout(60)
@pytest.mark.parametrize("role", CALLERS, ids=lambda role: role or "anonymous")
async def test_every_socket_message_type_answers_each_role_as_the_matrix_says(
    members, world, recorded_control, role
):
    from portal.consumers import COMMANDS

    user = members[role] if role else None
    communicator = await _socket(user)
    if role is None:
        assert await communicator.receive_output(timeout=5) == {"type": "websocket.close", "code": 4401}
        await communicator.disconnect()
        return
    assert (await communicator.receive_json_from(timeout=5))["type"] == "snapshot"
    for command, entry in COMMANDS.items():
        await communicator.send_json_to(_message(command, world["robot"].pk))
        reply = await _reply_to(communicator, command)
        where = f"{command} as {role} (needs {entry.ability}): {reply['detail']}"
        if allowed(role, entry.ability):
            assert reply["ok"] is True, where
        else:
            assert reply["ok"] is False and f"({entry.ability})" in reply["detail"], where
    await communicator.disconnect()


async def _reply_to(communicator, ref: str) -> dict:
    for _ in range(50):  # pushes (status, leases) may come between; bounded
        message = await communicator.receive_json_from(timeout=5)
        if message.get("type") == "command.result" and message.get("ref") == ref:
            return message
    raise AssertionError(f"no answer to {ref}")
