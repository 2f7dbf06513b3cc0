"""The POST views behind the buttons: leases, stop and teleop, refused for viewers and non-holders."""

import json

import pytest
from django.urls import reverse

from access import leases
from audit.models import AuditEntry


def _post(client, path, body):
    return client.post(
        path, json.dumps(body), content_type="application/json", HTTP_ACCEPT="application/json"
    )


@pytest.fixture
def fake_control(monkeypatch):
    """Record what reaches execution.control instead of talking to robots; the checks are the real ones."""
    import importlib

    import execution

    real = importlib.import_module("execution.control")
    calls = []

    class Control:
        teleop_grants = staticmethod(real.teleop_grants)

        @staticmethod
        def stop(robots, user):
            calls.append(("stop", sorted(robot.name for robot in robots), user.username))

        @staticmethod
        def teleop_with(grant, user, linear, angular):
            v, w = grant.clamp(linear, angular)
            calls.append(("teleop", grant.robot_name, user.username, v, w))
            return v, w

    monkeypatch.setitem(__import__("sys").modules, "execution.control", Control)
    monkeypatch.setattr(execution, "control", Control, raising=False)
    return calls


def test_operator_takes_and_releases_a_lease(client_for, operator, fleet):
    robot = fleet["turtlebot"]
    client = client_for(operator)
    reply = _post(client, reverse("robot-lease", args=[robot.pk]), {"action": "take"})
    assert reply.status_code == 200
    assert reply.json()["holder"] == "otto"
    assert leases.holder(robot) == operator
    reply = _post(client, reverse("robot-lease", args=[robot.pk]), {"action": "release"})
    assert reply.json()["holder"] is None


def test_second_operator_cannot_take_a_held_robot(client, operator, second_operator, fleet):
    robot = fleet["turtlebot"]
    leases.take(operator, robot)
    client.force_login(second_operator)
    reply = _post(client, reverse("robot-lease", args=[robot.pk]), {"action": "take"})
    assert reply.status_code == 403
    assert "held by otto" in reply.json()["detail"]


def test_bad_lease_action_is_named(client_for, operator, fleet):
    reply = _post(
        client_for(operator), reverse("robot-lease", args=[fleet["turtlebot"].pk]), {"action": "grab"}
    )
    assert reply.status_code == 422
    assert "action" in reply.json()["detail"]


def test_viewer_cannot_stop_or_teleop(client_for, viewer, fleet, fake_control):
    client = client_for(viewer)
    assert _post(client, reverse("stop"), {"robots": "all"}).status_code == 403
    reply = _post(client, reverse("robot-teleop", args=[fleet["turtlebot"].pk]), {"linear": 0.1})
    assert reply.status_code == 403
    assert "may not stop" in reply.json()["detail"]
    assert fake_control == []
    assert AuditEntry.objects.filter(action="access.refused", user=viewer).count() == 2


def test_stop_all_reaches_robots_held_by_someone_else(client, operator, second_operator, fleet, fake_control):
    """A lease keeps others from driving a robot, never from stopping it."""
    leases.take(operator, fleet["turtlebot"])
    client.force_login(second_operator)
    reply = _post(client, reverse("stop"), {"robots": "all"})
    assert reply.status_code == 200
    ((verb, names, who),) = fake_control
    assert (verb, sorted(names), who) == ("stop", ["husky", "turtlebot"], "olga")


def test_teleop_is_clamped_to_the_robot_limits(client_for, operator, fleet, fake_control):
    reply = _post(
        client_for(operator),
        reverse("robot-teleop", args=[fleet["turtlebot"].pk]),
        {"linear": 5, "angular": -9},
    )
    assert reply.status_code == 200
    assert fake_control == [("teleop", "turtlebot", "otto", 0.22, -2.84)]


def test_teleop_with_a_bad_number_names_the_field(client_for, operator, fleet, fake_control):
    reply = _post(
        client_for(operator), reverse("robot-teleop", args=[fleet["turtlebot"].pk]), {"linear": "fast"}
    )
    assert reply.status_code == 422
    assert "linear" in reply.json()["detail"]


def test_plain_stop_form_redirects_back_with_a_message(client_for, operator, fleet, fake_control):
    response = client_for(operator).post(
        reverse("stop"), {"robots": "all"}, HTTP_REFERER="/robots/", follow=True
    )
    assert response.redirect_chain[0][0] == "/robots/"
    assert "Stopped husky, turtlebot." in response.content.decode()
