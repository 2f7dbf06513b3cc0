"""Alerts: one open per kind and robot, pushed live, acknowledged and resolved by operators, audited."""

import asyncio

import pytest
from asgiref.sync import sync_to_async
from channels.layers import get_channel_layer
from channels.testing import WebsocketCommunicator

import alerts
import live
from alerts.models import Alert
from audit.models import AuditEntry
from robots.links import check_battery
from robots.models import Robot

pytestmark = pytest.mark.django_db(transaction=True)


@pytest.fixture
def robot():
    return Robot.objects.create(name="tb", endpoint="ws://127.0.0.1:1")


def test_a_repeat_counts_on_the_open_alert_and_a_new_one_opens_after_it_is_resolved(robot, operator):
    first = alerts.raise_alert("robot_stuck", robot, "blocked near (1.0, 2.0)")
    again = alerts.raise_alert("robot_stuck", robot, "blocked by husky at A")
    assert again.pk == first.pk
    again.refresh_from_db()
    assert (again.count, again.message, again.severity) == (2, "blocked by husky at A", "warning")
    assert alerts.raise_alert("step_failed", robot, "x").pk != first.pk  # another kind: its own alert
    from alerts import service

    service.resolve(first.pk, operator, "moved the husky")
    assert alerts.raise_alert("robot_stuck", robot, "blocked again").pk != first.pk
    assert AuditEntry.objects.filter(action="alert.raise").count() == 3
    assert AuditEntry.objects.get(action="alert.resolve").user == operator


def test_an_unknown_kind_is_logged_not_raised_into_the_caller(robot, caplog):
    assert alerts.raise_alert("on_fire", robot, "?") is None
    assert "not stored" in caplog.text
    assert not Alert.objects.exists()


def test_the_end_of_a_condition_resolves_its_alert(robot):
    alerts.raise_alert("robot_offline", robot, "link lost")
    resolved = alerts.resolve_alert("robot_offline", robot, "link up again")
    assert resolved.resolved_at is not None and resolved.resolved_by is None
    assert resolved.resolution == "link up again"
    assert alerts.resolve_alert("robot_offline", robot) is None  # nothing open any more


def test_a_low_battery_raises_once_and_a_charged_one_resolves(robot):
    assert check_battery(robot.pk, {"percentage": 0.12}) == "low"
    assert check_battery(robot.pk, {"percentage": 0.11}) == "low"
    alert = Alert.objects.get(kind="low_battery")
    assert alert.count == 2 and "11%" in alert.message
    assert check_battery(robot.pk, {"percentage": 0.25}) is None  # between the two marks: no change
    assert check_battery(robot.pk, {"percentage": float("nan")}) is None  # not measured
    assert check_battery(robot.pk, {"percentage": 80}) == "ok"  # a driver that publishes percent
    alert.refresh_from_db()
    assert alert.resolved_at is not None


def test_stopping_every_robot_raises_one_emergency_stop(robot, operator):
    from execution.control import stop

    Robot.objects.create(name="other", endpoint="ws://127.0.0.1:2")
    stop(["tb"], operator)  # one robot of two: not an emergency stop
    assert not Alert.objects.filter(kind="emergency_stop").exists()
    stop(list(Robot.objects.all()), operator)
    alert = Alert.objects.get(kind="emergency_stop")
    assert alert.robot is None and alert.severity == "critical" and "otto" in alert.message


# ----- the API -----
def test_viewers_list_alerts_and_may_not_handle_them(client_for, viewer, robot):
    alert = alerts.raise_alert("step_failed", robot, "instruction #1: no odometry for 3 s")
    client = client_for(viewer)
    listed = client.get("/api/alerts").json()
    assert [(a["id"], a["kind"], a["robot"], a["status"]) for a in listed] == [
        (alert.pk, "step_failed", "tb", "open")
    ]
    assert client.post(f"/api/alerts/{alert.pk}/acknowledge").status_code == 403
    assert (
        client.post(f"/api/alerts/{alert.pk}/resolve", {}, content_type="application/json").status_code == 403
    )
    assert client.get("/api/alerts?status=bogus").status_code == 422


def test_operators_acknowledge_then_resolve_and_both_are_audited(client_for, operator, robot):
    alert = alerts.raise_alert("executor_lost", robot, "instruction #3: executor lost")
    client = client_for(operator)
    acked = client.post(f"/api/alerts/{alert.pk}/acknowledge").json()
    assert (acked["status"], acked["acknowledged_by"]) == ("acknowledged", "otto")
    done = client.post(
        f"/api/alerts/{alert.pk}/resolve", {"note": "worker restarted"}, content_type="application/json"
    )
    assert done.json()["status"] == "resolved" and done.json()["resolution"] == "worker restarted"
    again = client.post(f"/api/alerts/{alert.pk}/resolve", {}, content_type="application/json")
    assert again.status_code == 409 and again.json()["detail"].startswith("alert_id: alert")
    assert client.post("/api/alerts/99999/acknowledge").status_code == 404
    assert client.get("/api/alerts").json() == []
    assert [a["id"] for a in client.get("/api/alerts?status=resolved").json()] == [alert.pk]
    assert list(AuditEntry.objects.filter(user=operator).values_list("action", flat=True).order_by("at")) == [
        "alert.acknowledge",
        "alert.resolve",
    ]


def test_the_page_lists_open_alerts_with_buttons_for_operators_only(client_for, viewer, operator, robot):
    alerts.raise_alert("robot_stuck", robot, "blocked by husky at A")
    page = client_for(viewer).get("/alerts/").content.decode()
    assert "blocked by husky at A" in page and 'id="alerts-badge"' in page and "data-act" not in page
    page = client_for(operator).get("/alerts/").content.decode()
    assert 'data-act="acknowledge"' in page and 'data-act="resolve"' in page


# ----- live -----
@pytest.mark.asyncio
async def test_every_change_is_pushed_with_the_open_count(robot, operator):
    from alerts import service

    layer = get_channel_layer()
    channel = await layer.new_channel()
    await layer.group_add(live.ALERTS_GROUP, channel)
    try:
        alert = await sync_to_async(alerts.raise_alert)("robot_offline", robot, "link lost")
        raised = await asyncio.wait_for(layer.receive(channel), 5)
        assert (raised["type"], raised["open_count"], raised["alert"]["message"]) == (
            "alert.update",
            1,
            "link lost",
        )
        await sync_to_async(service.resolve)(alert.pk, operator)
        resolved = await asyncio.wait_for(layer.receive(channel), 5)
        assert (resolved["alert"]["status"], resolved["open_count"]) == ("resolved", 0)
    finally:
        await layer.group_discard(live.ALERTS_GROUP, channel)


@pytest.mark.asyncio
async def test_the_alerts_socket_sends_the_open_count_first_then_each_update(viewer, robot):
    from fleet.asgi import application
    from tests.portal.test_websockets import _session_cookie

    await sync_to_async(alerts.raise_alert)("robot_stuck", robot, "stalled")
    headers = [(b"origin", b"http://127.0.0.1"), (b"cookie", await _session_cookie(viewer))]
    communicator = WebsocketCommunicator(application, "/ws/alerts/", headers=headers)
    assert (await communicator.connect())[0]
    try:
        snapshot = await communicator.receive_json_from(timeout=5)
        assert (snapshot["type"], snapshot["open_count"]) == ("alerts.snapshot", 1)
        assert snapshot["alerts"][0]["message"] == "stalled"
        await sync_to_async(alerts.raise_alert)("step_failed", robot, "no odometry for 3 s")
        update = await communicator.receive_json_from(timeout=5)
        assert (update["type"], update["open_count"], update["alert"]["kind"]) == (
            "alert.update",
            2,
            "step_failed",
        )
    finally:
        await communicator.disconnect()
