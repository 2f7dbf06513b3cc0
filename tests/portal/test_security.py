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
from robots.models import Robot, robot_name_from, validate_robot_name
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
    # even the right password is refused from that address for the cool-off ...
    assert client.post(login_url, {"username": fleet_admin.username, "password": PASSWORD}).status_code == 429
    # ... while the admin logs in from another one: nobody can lock the admin out from elsewhere
    elsewhere = client.post(
        login_url, {"username": fleet_admin.username, "password": PASSWORD}, REMOTE_ADDR="10.1.2.3"
    )
    assert elsewhere.status_code == 302


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

    monkeypatch.setattr(dispatch, "launch", lambda task, pk: None)  # stored, not run
    body = {"robot_ids": [fleet["turtlebot"].pk], "destination": {"x": 0.5, "y": 0.4, "yaw": 1.57}}
    reply = client_for(operator).post("/api/instructions", body, content_type="application/json")
    assert reply.status_code == 201, reply.content
    step = Instruction.objects.get(pk=reply.json()["id"]).parse["steps"][0]
    assert step["destination"] == {"name": "", "x": 0.5, "y": 0.4, "yaw": 1.57}
    assert "facing 90°" in reply.json()["text"]
    bad = {"robot_ids": [fleet["turtlebot"].pk], "destination": {"x": 0.5, "y": 0.4, "yaw": 99}}
    reply = client_for(operator).post("/api/instructions", bad, content_type="application/json")
    assert reply.status_code == 422 and "yaw" in str(reply.json()["detail"])
