"""Production settings, login throttling, session expiry, the append-only audit, and names that are only data."""

import os
import secrets
import subprocess
import sys
from pathlib import Path

import pytest
from django.core.exceptions import ValidationError

from audit.models import AppendOnlyError, AuditEntry
from execution.models import Execution, Instruction
from robots.models import Binding, Robot, robot_name_from, validate_robot_name
from tests.conftest import PASSWORD

BASE_DIR = Path(__file__).resolve().parents[2]


def _check_deploy(tmp_path, **env) -> subprocess.CompletedProcess:
    environment = {
        **os.environ,
        "FLEET_VAR_DIR": str(tmp_path),
        "SECRET_KEY": secrets.token_urlsafe(60),
        "ALLOWED_HOSTS": "fleet.example.com",
        **env,
    }
    return subprocess.run(
        [sys.executable, "manage.py", "check", "--deploy", "--fail-level", "WARNING"],
        cwd=BASE_DIR,
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_check_deploy_finds_nothing_behind_tls(tmp_path):
    result = _check_deploy(tmp_path, FLEET_BEHIND_TLS="true")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "System check identified no issues" in result.stdout


def test_without_the_switch_check_deploy_names_what_it_turns_on(tmp_path):
    result = _check_deploy(tmp_path, FLEET_BEHIND_TLS="false")
    assert result.returncode != 0
    for warning in ("security.W004", "security.W008", "security.W012", "security.W016"):
        assert warning in result.stderr + result.stdout


# --- login throttling and sessions ------------------------------------------------------------------------------


@pytest.mark.parametrize("login_url", ["/login/", "/admin/login/"])
def test_thirty_wrong_passwords_are_refused_after_a_few(client, fleet_admin, settings, login_url):
    answers = [
        client.post(login_url, {"username": fleet_admin.username, "password": f"wrong-{i}"}).status_code
        for i in range(30)
    ]
    limit = settings.AXES_FAILURE_LIMIT
    assert answers[: limit - 1] == [200] * (limit - 1)  # the form again, "didn't match"
    assert answers[limit:] == [429] * (30 - limit)  # locked out
    # even the right password is refused for the cool-off, from this address and from any other
    assert client.post(login_url, {"username": fleet_admin.username, "password": PASSWORD}).status_code == 429
    elsewhere = client.post(
        login_url, {"username": fleet_admin.username, "password": PASSWORD}, REMOTE_ADDR="10.1.2.3"
    )
    assert elsewhere.status_code == 429


def _guess(client, username: str, i: int, **meta) -> int:
    return client.post("/login/", {"username": username, "password": f"wrong-{i}"}, **meta).status_code


def test_rotating_x_forwarded_for_from_an_untrusted_peer_is_throttled(client, fleet_admin, settings):
    assert settings.FLEET_TRUSTED_PROXIES == []  # the default: nobody's X-Forwarded-For is believed
    answers = [
        _guess(client, fleet_admin.username, i, HTTP_X_FORWARDED_FOR=f"203.0.113.{i}") for i in range(10)
    ]
    limit = settings.AXES_FAILURE_LIMIT
    assert answers[limit:] == [429] * (10 - limit)
    # a locked account cannot log in with a new X-Forwarded-For either
    fresh = client.post(
        "/login/",
        {"username": fleet_admin.username, "password": PASSWORD},
        HTTP_X_FORWARDED_FOR="198.51.100.77",
    )
    assert fresh.status_code == 429


def test_a_locked_account_stays_locked_behind_a_trusted_proxy(client, fleet_admin, settings):
    settings.FLEET_TRUSTED_PROXIES = ["10.77.0.10"]
    proxied = {"REMOTE_ADDR": "10.77.0.10"}
    for i in range(settings.AXES_FAILURE_LIMIT):  # each guess from a client of its own, as the proxy says
        _guess(client, fleet_admin.username, i, HTTP_X_FORWARDED_FOR=f"203.0.113.{i}", **proxied)
    fresh = client.post(
        "/login/",
        {"username": fleet_admin.username, "password": PASSWORD},
        HTTP_X_FORWARDED_FOR="198.51.100.77",
        **proxied,
    )
    assert fresh.status_code == 429


def test_thirty_usernames_from_one_address_are_throttled(client, viewer, settings):
    answers = [_guess(client, f"someone{i}", i) for i in range(30)]
    limit = settings.AXES_FAILURE_LIMIT
    assert answers[limit:] == [429] * (30 - limit)
    # the address is locked, even for a real account with its right password ...
    assert client.post("/login/", {"username": viewer.username, "password": PASSWORD}).status_code == 429
    # ... while that account logs in from another address
    elsewhere = client.post(
        "/login/", {"username": viewer.username, "password": PASSWORD}, REMOTE_ADDR="10.1.2.3"
    )
    assert elsewhere.status_code == 302


def test_the_client_address_is_the_peer_unless_the_peer_is_a_trusted_proxy(rf, settings):
    from portal.clientaddr import client_address

    def seen(peer: str, forwarded: str | None = None) -> str:
        meta = {"REMOTE_ADDR": peer} | ({"HTTP_X_FORWARDED_FOR": forwarded} if forwarded else {})
        return client_address(rf.post("/login/", **meta))

    settings.FLEET_TRUSTED_PROXIES = []
    assert seen("198.51.100.1", "203.0.113.9") == "198.51.100.1"
    settings.FLEET_TRUSTED_PROXIES = ["10.77.0.0/24"]
    assert seen("198.51.100.1", "203.0.113.9") == "198.51.100.1"  # not a proxy of ours: its header is ignored
    assert seen("10.77.0.10", "203.0.113.9") == "203.0.113.9"
    # read from the right: what the client put in front of the proxy's own entry is never believed
    assert seen("10.77.0.10", "1.2.3.4, 203.0.113.9") == "203.0.113.9"
    assert seen("10.77.0.10", "203.0.113.9, 10.77.0.11") == "203.0.113.9"  # through two proxies of ours
    assert seen("10.77.0.10", "not-an-address") == "10.77.0.10"
    assert seen("10.77.0.10") == "10.77.0.10"


def test_web_servers_never_rewrite_the_peer_from_forwarded_headers(tmp_path):
    from fleet.run import Setup, programs

    (web,) = [p for p in programs(Setup.from_env({"FLEET_VAR_DIR": str(tmp_path)})) if p.name == "web"]
    assert "--no-proxy-headers" in web.command  # uvicorn's default trusts 127.0.0.1's X-Forwarded-For
    for unit in ("deploy/systemd/fleet-web.service", "deploy/supervisord.conf"):
        text = (BASE_DIR / unit).read_text()
        assert "--no-proxy-headers" in text and "--proxy-headers" not in text.replace(
            "--no-proxy-headers", ""
        )
    nginx = (BASE_DIR / "deploy/nginx/fleet.conf").read_text()
    assert "$proxy_add_x_forwarded_for" not in nginx and "X-Forwarded-For $remote_addr" in nginx


def test_a_session_ends_after_a_working_day(client, viewer, settings):
    assert settings.SESSION_COOKIE_AGE == 12 * 3600
    response = client.post("/login/", {"username": viewer.username, "password": PASSWORD})
    assert response.status_code == 302
    cookie = response.cookies["sessionid"]
    assert int(cookie["max-age"]) == settings.SESSION_COOKIE_AGE and cookie["httponly"]


# --- the audit trail is append-only, below the admin too ---------------------------------------------------------


def test_an_audit_entry_is_never_changed_or_deleted(db, viewer):
    from audit import records as audit

    entry = audit.record(viewer, "test.entry", "first")
    entry.action = "rewritten"
    with pytest.raises(AppendOnlyError):
        entry.save()
    with pytest.raises(AppendOnlyError):
        entry.delete()
    with pytest.raises(AppendOnlyError):
        AuditEntry.objects.filter(pk=entry.pk).update(action="rewritten")
    with pytest.raises(AppendOnlyError):
        AuditEntry.objects.all().delete()
    assert AuditEntry.objects.get(pk=entry.pk).action == "test.entry"
    audit.record_many(viewer, "test.many", [("second", entry.at, {})])  # adding stays possible
    assert AuditEntry.objects.count() == 2


def test_deleting_a_user_keeps_their_audit_entries(db, viewer):
    from audit import records as audit

    entry = audit.record(viewer, "test.entry", "kept")
    viewer.delete()
    kept = AuditEntry.objects.get(pk=entry.pk)
    assert kept.user is None and kept.action == "test.entry" and kept.target == "kept"


# --- names are data ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["husky", "tb3_0", "robot-2", "Spot", "x1"])
def test_a_robot_name_is_one_word(name):
    validate_robot_name(name)


@pytest.mark.parametrize(
    "name", ["x and husky", "and", "then", "ALL", "42", "robot 1", "a.b", "", "-x", "x;y"]
)
def test_a_name_that_would_read_as_words_is_refused(name):
    with pytest.raises(ValidationError):
        validate_robot_name(name)


@pytest.mark.parametrize(
    ("raw", "name"),
    [
        ("x and husky", "x-and-husky"),
        ("127.0.0.1-9091", "127-0-0-1-9091"),
        ("and", "robot-and"),
        ("7", "robot-7"),
    ],
)
def test_registration_makes_a_valid_name_of_whatever_a_robot_calls_itself(raw, name):
    assert robot_name_from(raw) == name
    validate_robot_name(name)


def test_renaming_a_robot_in_the_admin_refuses_a_name_with_spaces(client, fleet_admin, fleet):
    husky = fleet["husky"]
    client.force_login(fleet_admin)
    form = {"name": "x and husky", "endpoint": husky.endpoint, "drive": husky.drive, "max_linear": 1.0}
    response = client.post(f"/admin/robots/robot/{husky.pk}/change/", {**form, "max_angular": 1.0})
    assert response.status_code == 200  # the form again, with the error
    assert "letters, digits, dashes and underscores" in response.content.decode()
    husky.refresh_from_db()
    assert husky.name == "husky"


def test_click_to_move_sends_robot_ids_and_a_name_is_never_read_as_words(
    client_for, operator, fleet, small_map
):
    """A robot named "x and husky" (stored before names were checked) is moved by its id: husky stays put."""
    husky = fleet["husky"]
    Robot.objects.filter(pk=husky.pk).update(link_status=Robot.Link.ONLINE, state=Robot.State.READY)
    odd = Robot.objects.create(
        name="x and husky",
        endpoint="ws://127.0.0.1:1",
        link_status=Robot.Link.ONLINE,
        state=Robot.State.READY,
    )
    for role in ("move", "odometry"):  # a robot that can move (one that cannot is refused at dispatch)
        Binding.objects.create(robot=odd, action=role, target=f"/odd/{role}")
    place = small_map.locations.get(name="B")
    reply = client_for(operator).post(
        "/api/instructions",
        {"robot_ids": [odd.pk], "destination": {"location": place.pk}},
        content_type="application/json",
    )
    assert reply.status_code == 201, reply.content
    instruction = Instruction.objects.get(pk=reply.json()["id"])
    (step,) = instruction.parse["steps"]
    assert step["robots"] == ["x and husky"] and step["destination"]["name"] == "B"
    assert list(Execution.objects.filter(instruction=instruction).values_list("robot__name", flat=True)) == [
        "x and husky"
    ]
    assert not Execution.objects.filter(robot=husky).exists()


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"robot_ids": [1]}, "destination"),
        ({"robot_ids": [1], "destination": {"x": 1.0}}, "destination"),
        ({"robot_ids": [1], "destination": {"location": 1, "x": 1.0, "y": 2.0}}, "destination"),
        ({"robot_ids": [999999], "destination": {"x": 1.0, "y": 2.0}}, "robot_ids"),
        ({"robot_ids": [10**30], "destination": {"x": 1.0, "y": 2.0}}, "robot_ids"),
        ({"text": "move husky to A", "robot_ids": [1], "destination": {"x": 1.0, "y": 2.0}}, "text"),
        ({"text": "   "}, "text"),
    ],
)
def test_a_bad_click_to_move_names_the_field(client_for, operator, fleet, body, field):
    reply = client_for(operator).post("/api/instructions", body, content_type="application/json")
    assert reply.status_code == 422
    assert field in str(reply.json()["detail"])


def test_a_goal_dragged_on_the_map_keeps_its_heading(client_for, operator, fleet, monkeypatch):
    from execution import dispatch
    from execution.models import Instruction

    monkeypatch.setattr(dispatch.executor, "wake", lambda robot_ids: None)  # stored, not run
    body = {"robot_ids": [fleet["turtlebot"].pk], "destination": {"x": 0.5, "y": 0.4, "yaw": 1.57}}
    reply = client_for(operator).post("/api/instructions", body, content_type="application/json")
    assert reply.status_code == 201, reply.content
    step = Instruction.objects.get(pk=reply.json()["id"]).parse["steps"][0]
    assert step["destination"] == {"name": "", "x": 0.5, "y": 0.4, "yaw": 1.57}
    assert "facing 90°" in reply.json()["text"]
    bad = {"robot_ids": [fleet["turtlebot"].pk], "destination": {"x": 0.5, "y": 0.4, "yaw": 99}}
    reply = client_for(operator).post("/api/instructions", bad, content_type="application/json")
    assert reply.status_code == 422 and "yaw" in str(reply.json()["detail"])


def test_a_refused_request_is_logged_in_one_line(client_for, viewer, caplog):
    client = client_for(viewer)
    with caplog.at_level("WARNING", logger="django.request"):
        assert client.get("/audit/").status_code == 403
    (record,) = [r for r in caplog.records if r.name == "django.request"]
    assert record.exc_info is None and record.exc_text is None  # no traceback
    line = caplog.handler.format(record)
    assert "\n" not in line and "/audit/" in line and viewer.username in line  # the path and the reason
