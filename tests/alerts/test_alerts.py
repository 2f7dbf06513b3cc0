"""Alerts: one per event, pushed live, acknowledged and resolved by operators, audited."""

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


def test_each_stop_of_every_robot_is_its_own_alert_with_its_own_time_and_person(
    robot, operator, second_operator
):
    from execution.control import stop

    Robot.objects.create(name="other", endpoint="ws://127.0.0.1:2")
    stop(["tb"], operator)  # one robot of two: not an emergency stop
    assert not Alert.objects.filter(kind="emergency_stop").exists()
    stop(list(Robot.objects.all()), operator)
    stop(list(Robot.objects.all()), second_operator)
    first, last = Alert.objects.filter(kind="emergency_stop").order_by("raised_at")
    assert first.robot is None and first.severity == "critical" and first.count == 1
    assert f"by {operator.username}" in first.message and f"by {second_operator.username}" in last.message
    assert first.raised_at < last.raised_at  # each keeps the time of its own stop


def _execution(robot, number: int):
    from execution.models import Execution, Instruction

    instruction = Instruction.objects.create(text=f"move tb to A #{number}", status="running")
    return Execution.objects.create(instruction=instruction, robot=robot, status="running")


def test_a_stall_and_the_failure_it_ends_in_are_one_alert_and_the_next_execution_another(robot):
    """The runner's step_failed after a stall's robot_stuck is the same event (execution.runner, handlers)."""
    first, second = _execution(robot, 1), _execution(robot, 2)
    stuck = alerts.raise_alert("robot_stuck", robot, "tb: no progress for 3 s (trying again)", first.event)
    failed = alerts.raise_alert(
        "step_failed", robot, "instruction #1: tb: blocked by husky at A", first.event
    )
    assert failed.pk == stuck.pk and Alert.objects.count() == 1
    failed.refresh_from_db()
    assert (failed.kind, failed.count, failed.message) == (
        "step_failed",
        2,
        "instruction #1: tb: blocked by husky at A",
    )
    assert failed.raised_at == stuck.raised_at  # the time the event began
    again = alerts.raise_alert("robot_stuck", robot, "tb: no progress for 3 s (trying again)", second.event)
    assert again.pk != stuck.pk and Alert.objects.open().count() == 2  # a new execution: a new event


def test_an_event_a_person_has_dealt_with_is_not_raised_again(robot, operator):
    from alerts import service

    execution = _execution(robot, 1)
    stuck = alerts.raise_alert("robot_stuck", robot, "tb: no progress (trying again)", execution.event)
    service.acknowledge(stuck.pk, operator)
    failed = alerts.raise_alert("step_failed", robot, "instruction #1: tb: stuck", execution.event)
    assert (failed.pk, failed.status) == (stuck.pk, "acknowledged")  # no new toast: count > 1, not open
    service.resolve(stuck.pk, operator, "moved the box")
    repeat = alerts.raise_alert("step_failed", robot, "instruction #1: tb: stuck", execution.event)
    assert (repeat.pk, repeat.status, repeat.count) == (stuck.pk, "resolved", 3)
    assert service.open_count() == 0 and Alert.objects.count() == 1


def test_a_condition_a_person_resolved_early_is_not_raised_again_until_it_ends(robot, operator):
    from alerts import service

    check_battery(robot.pk, {"percentage": 0.12})
    low = Alert.objects.get(kind="low_battery")
    service.resolve(low.pk, operator, "charger on its way")
    check_battery(robot.pk, {"percentage": 0.11})  # still low: the same event
    assert service.open_count() == 0 and Alert.objects.count() == 1
    check_battery(robot.pk, {"percentage": 0.9})  # charged: the event ended
    check_battery(robot.pk, {"percentage": 0.1})  # low again: a new event
    assert Alert.objects.open().get(kind="low_battery").pk != low.pk
    low.refresh_from_db()
    assert low.ended_at is not None and low.count == 2


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
