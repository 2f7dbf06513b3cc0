"""The pages' WebSockets: session auth, snapshot first, then deltas; commands refused for viewers and non-holders."""

import asyncio
import sys
import threading
import time

import pytest
from asgiref.sync import sync_to_async
from channels.testing import WebsocketCommunicator

import live
from access import leases
from access.models import ControlLease
from fleet.asgi import application
from robots.models import StateTransition
from robots.poses import store_poses

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.asyncio, pytest.mark.timeout(30)]


@sync_to_async
def _session_cookie(user) -> bytes:
    from django.test import Client

    client = Client()
    client.force_login(user)
    return f"sessionid={client.cookies['sessionid'].value}".encode()


async def _connect(path: str, user=None) -> WebsocketCommunicator:
    headers = [(b"origin", b"http://127.0.0.1")]
    if user is not None:
        headers.append((b"cookie", await _session_cookie(user)))
    communicator = WebsocketCommunicator(application, path, headers=headers)
    connected, _ = await communicator.connect()
    assert connected
    return communicator


async def _pushes(communicator, count: int, timeout: float = 5) -> list[dict]:
    """The pushes of the next frames until `count` have come, a batch frame's each in turn (the pushes that come
    together go to a page in one frame: portal.fanout.EventFanout.GATHER_S)."""
    got: list[dict] = []
    while len(got) < count:
        frame = await communicator.receive_json_from(timeout=timeout)
        got += frame["messages"] if frame.get("type") == "batch" else [frame]
    return got


async def test_anonymous_is_closed_with_4401(fleet):
    communicator = await _connect("/ws/fleet/")
    assert await communicator.receive_output(timeout=5) == {"type": "websocket.close", "code": 4401}
    await communicator.disconnect()


async def test_user_without_view_permission_is_closed_with_4403(fleet):
    from django.contrib.auth.models import User

    nobody = await sync_to_async(User.objects.create_user)("nobody", password="x" * 12)
    communicator = await _connect("/ws/fleet/", nobody)
    assert await communicator.receive_output(timeout=5) == {"type": "websocket.close", "code": 4403}
    await communicator.disconnect()


async def test_unknown_robot_is_closed_with_4404(viewer, fleet):
    communicator = await _connect("/ws/robots/99999/", viewer)
    assert await communicator.receive_output(timeout=5) == {"type": "websocket.close", "code": 4404}
    await communicator.disconnect()


async def test_snapshot_first_then_deltas(viewer, operator, fleet):
    communicator = await _connect("/ws/fleet/", viewer)
    snapshot = await communicator.receive_json_from(timeout=5)
    assert snapshot["type"] == "snapshot"
    by_name = {robot["name"]: robot for robot in snapshot["robots"]}
    assert set(by_name) == {"turtlebot", "husky"}
    assert by_name["turtlebot"]["state"] == "ready" and by_name["turtlebot"]["holder"] is None

    turtlebot = fleet["turtlebot"]

    @sync_to_async
    def change():
        turtlebot.state = "motion"
        turtlebot.save()
        live.robot_status(turtlebot)  # outside a transaction: sent at once
        record = StateTransition.objects.create(
            robot=turtlebot, from_state="ready", to_state="motion", reason="go"
        )
        live.transition(turtlebot, record)
        leases.take(operator, turtlebot)  # pushes the lease itself
        live.goal(turtlebot, "A", 0.2, 0.2)

    await change()
    status, transition, lease, goal = await _pushes(communicator, 4)
    assert status["type"] == "robot.status" and status["state"] == "motion"
    assert (transition["type"], transition["to_state"], transition["reason"]) == (
        "robot.transition",
        "motion",
        "go",
    )
    assert lease == {**lease, "type": "lease.update", "robot": "turtlebot", "holder": "otto"}
    assert (goal["type"], goal["name"], goal["x"]) == ("robot.goal", "A", 0.2)
    await communicator.disconnect()


async def test_snapshot_carries_the_holder_and_the_last_pose(viewer, operator, fleet):

    turtlebot = fleet["turtlebot"]
    await sync_to_async(leases.take)(operator, turtlebot)
    pose = {"id": turtlebot.pk, "x": 1.0, "y": 2.0, "yaw": 0.5, "v": 0.1, "w": 0.0, "t": time.time()}
    await sync_to_async(store_poses)([pose])
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", viewer)
    snapshot = await communicator.receive_json_from(timeout=5)
    assert snapshot["robots"][0]["holder"] == "otto"
    assert snapshot["robots"][0]["pose"] == pose
    await communicator.disconnect()


async def test_pose_batches_reach_the_dashboard_and_the_robot_page_gets_only_its_own(viewer, fleet):
    from channels.layers import get_channel_layer

    from portal.fanout import decode

    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    dashboard = await _connect("/ws/fleet/", viewer)
    page = await _connect(f"/ws/robots/{husky.pk}/", viewer)
    await dashboard.receive_json_from(timeout=5)
    await page.receive_json_from(timeout=5)
    batch = [
        {"id": turtlebot.pk, "x": 1.0, "y": 1.0, "yaw": 0.0, "v": 0.2, "w": 0.0, "t": 1.0},
        {"id": husky.pk, "x": 2.0, "y": 2.0, "yaw": 0.0, "v": 0.5, "w": 0.0, "t": 1.0},
    ]
    await get_channel_layer().group_send(live.POSES_GROUP, live.poses(batch))
    assert decode(await dashboard.receive_json_from(timeout=5)) == batch
    assert decode(await page.receive_json_from(timeout=5)) == [batch[1]]
    await dashboard.disconnect()
    await page.disconnect()


async def test_viewer_stop_over_the_socket_is_refused(viewer, fleet):
    communicator = await _connect("/ws/fleet/", viewer)
    await communicator.receive_json_from(timeout=5)
    await communicator.send_json_to({"command": "stop", "robots": "all", "ref": 7})
    reply = await communicator.receive_json_from(timeout=5)
    assert reply["type"] == "command.result" and reply["ok"] is False and reply["ref"] == 7
    assert "may not stop" in reply["detail"]
    await communicator.disconnect()


async def test_teleop_of_a_robot_held_by_someone_else_is_refused(operator, second_operator, fleet):
    turtlebot = fleet["turtlebot"]
    await sync_to_async(leases.take)(operator, turtlebot)
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", second_operator)
    await communicator.receive_json_from(timeout=5)
    await communicator.send_json_to({"command": "teleop", "robot": turtlebot.pk, "linear": 0.1, "angular": 0})
    reply = await communicator.receive_json_from(timeout=5)
    assert reply["ok"] is False and "held by otto" in reply["detail"]
    assert await sync_to_async(ControlLease.objects.get)(robot=turtlebot) is not None
    await communicator.disconnect()


async def test_unknown_and_malformed_commands_are_answered_not_crashed(operator, fleet):
    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    await communicator.send_json_to({"command": "dance"})
    assert "unknown" in (await communicator.receive_json_from(timeout=5))["detail"]
    await communicator.send_json_to({"command": "teleop", "robot": fleet["turtlebot"].pk, "linear": "fast"})
    assert "linear: must be a number" in (await communicator.receive_json_from(timeout=5))["detail"]
    await communicator.send_json_to({"command": "stop", "robots": "some"})
    assert "robots:" in (await communicator.receive_json_from(timeout=5))["detail"]
    await communicator.send_json_to(["not", "an", "object"])
    assert (await communicator.receive_json_from(timeout=5))["ok"] is False
    await communicator.disconnect()


def _record_publishes(monkeypatch, record) -> None:
    """The sockets' rosbridge links (robots.rosbridge.pool) hand every publish to record(topic, message)."""

    class FakeLink:
        async def publish(self, topic, message, type_):
            record(topic, message)

    async def client(url, connect_timeout=2.0):
        return FakeLink()

    monkeypatch.setattr("robots.rosbridge.pool.client", client)


@pytest.fixture
def published(monkeypatch):
    """What the sockets' teleop publishes on the robots' links: (topic, linear x)."""
    sent = []
    _record_publishes(monkeypatch, lambda topic, message: sent.append((topic, message["linear"]["x"])))
    return sent


async def _teleop(communicator, robot, linear):
    await communicator.send_json_to({"command": "teleop", "robot": robot.pk, "linear": linear, "angular": 0})
    while True:
        reply = await communicator.receive_json_from(timeout=5)
        if reply.get("type") == "command.result":
            return reply


async def test_a_lease_taken_by_someone_else_stops_a_held_teleop_at_once(
    operator, fleet_admin, fleet, published
):
    """Repeats publish under the press's grant; the lease push drops it, so the next repeat is refused (the
    driver holds the lease from the first press: only an admin takes it over)."""
    turtlebot = fleet["turtlebot"]
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", operator)
    await communicator.receive_json_from(timeout=5)
    assert (await _teleop(communicator, turtlebot, 0.1))["ok"] is True
    assert (await _teleop(communicator, turtlebot, 5.0))[
        "detail"
    ] == "turtlebot: linear 0.22 m/s, angular 0.00 rad/s"
    await sync_to_async(leases.take)(fleet_admin, turtlebot)
    while not any(push.get("type") == "lease.update" for push in await _pushes(communicator, 1)):
        pass
    refused = await _teleop(communicator, turtlebot, 0.1)
    assert refused["ok"] is False and "held by ada" in refused["detail"]
    assert published == [("/cmd_vel", 0.1), ("/cmd_vel", 0.22)]
    await communicator.disconnect()


async def test_a_held_teleop_is_rechecked_while_held(operator, fleet_admin, fleet, published, monkeypatch):
    """Without any push (a lost message), the periodic re-check still finds the lease and says so."""
    from execution import control

    monkeypatch.setattr(control, "GRANT_S", 0.4)
    monkeypatch.setattr(live, "lease", lambda robot, lease=None: None)  # the push is lost
    turtlebot = fleet["turtlebot"]
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", operator)
    await communicator.receive_json_from(timeout=5)
    assert (await _teleop(communicator, turtlebot, 0.1))["ok"] is True
    await sync_to_async(leases.take)(fleet_admin, turtlebot)
    assert (await _teleop(communicator, turtlebot, 0.1))["ok"] is True  # the grant still stands
    said = await communicator.receive_json_from(timeout=5)  # the re-check, 0.2 s later
    assert said["ok"] is False and said["ref"] is None and "held by ada" in said["detail"]
    refused = await _teleop(communicator, turtlebot, 0.1)
    assert refused["ok"] is False and "held by ada" in refused["detail"]
    assert published == [("/cmd_vel", 0.1), ("/cmd_vel", 0.1)]
    await communicator.disconnect()


async def test_teleop_of_a_free_robot_takes_its_lease_for_the_driver(
    operator, second_operator, fleet, published
):
    """Driving needs the lease: the first press takes a free robot's (shown on every page); another operator's
    teleop is then refused."""
    turtlebot = fleet["turtlebot"]
    assert await sync_to_async(leases.holder)(turtlebot) is None
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", operator)
    await communicator.receive_json_from(timeout=5)
    assert (await _teleop(communicator, turtlebot, 0.1))["ok"] is True
    assert await sync_to_async(leases.holder)(turtlebot) == operator
    other = await _connect(f"/ws/robots/{turtlebot.pk}/", second_operator)
    await other.receive_json_from(timeout=5)
    refused = await _teleop(other, turtlebot, 0.1)
    assert refused["ok"] is False and "held by otto" in refused["detail"]
    assert published == [("/cmd_vel", 0.1)]
    await communicator.disconnect()
    await other.disconnect()


async def test_held_teleop_audits_changes_not_repeats(operator, fleet, published):
    from audit.models import AuditEntry

    turtlebot = fleet["turtlebot"]
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", operator)
    await communicator.receive_json_from(timeout=5)
    for linear in (0.1, 0.1, 0.1, 0.2, 0.2, 0.0):
        assert (await _teleop(communicator, turtlebot, linear))["ok"] is True
    await communicator.disconnect()

    @sync_to_async
    def audited():
        return [e.details["linear"] for e in AuditEntry.objects.filter(action="teleop").order_by("at", "pk")]

    seen = []
    for _ in range(50):
        seen = await audited()
        if len(seen) == 3:
            break
        await asyncio.sleep(0.05)
    assert seen == [0.1, 0.2, 0.0]
    assert len(published) == 6


async def test_a_link_that_is_down_is_said_in_words(operator, fleet):
    """No simulator on the robot's endpoint: the press is answered with the reason, nothing crashes."""
    turtlebot = fleet["turtlebot"]
    communicator = await _connect(f"/ws/robots/{turtlebot.pk}/", operator)
    await communicator.receive_json_from(timeout=5)
    reply = await _teleop(communicator, turtlebot, 0.1)
    assert reply["ok"] is False and "cannot reach ws://127.0.0.1:9091" in reply["detail"]
    await communicator.disconnect()


@pytest.fixture
def recorded(monkeypatch):
    """The order things happen in a stop: zeros published from the loop, then control.stop in a thread."""
    import execution

    events = []
    _record_publishes(
        monkeypatch,
        lambda topic, message: events.append(("published", topic, message.get("linear", {}).get("x"))),
    )

    class Control:
        @staticmethod
        def stop(robots, user, source="console"):
            names = sorted(getattr(robot, "name", robot) for robot in robots)  # robots, or names (submit's)
            events.append(("control.stop", names))
            return dict.fromkeys(names, "stopped")

    monkeypatch.setitem(__import__("sys").modules, "execution.control", Control)
    monkeypatch.setattr(execution, "control", Control, raising=False)
    return events


async def test_a_stop_publishes_zero_before_any_database_work(operator, fleet, recorded):
    from execution import coordination, fast_stop

    turtlebot = fleet["turtlebot"]
    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    await fast_stop.TARGETS._load()  # what connect started in the background, done now for the test
    await communicator.send_json_to({"command": "stop", "robots": [turtlebot.pk], "ref": 3})
    reply = await communicator.receive_json_from(timeout=5)
    assert reply["ok"] is True and reply["ref"] == 3
    assert recorded == [("published", "/cmd_vel", 0.0), ("control.stop", ["turtlebot"])]
    flag = await sync_to_async(coordination.connection().get)(coordination.key("stop", turtlebot.pk))
    assert flag is not None  # raised before the zero: a running instruction publishes nothing more
    await communicator.disconnect()


def _slow_bookkeeping(monkeypatch) -> tuple[list, threading.Event]:
    """Zeros published and control.stop recorded in order ("zero", "bookkeeping"); control.stop waits for the
    event (a large fleet's flags, second zeros, queues, leases and audit take seconds)."""
    import execution

    events, release = [], threading.Event()
    _record_publishes(monkeypatch, lambda topic, message: events.append("zero"))

    class Control:
        @staticmethod
        def stop(robots, user, source="console"):
            events.append("bookkeeping")
            release.wait(10)
            return {getattr(robot, "name", robot): "stopped" for robot in robots}  # robots, or submit's names

    monkeypatch.setitem(sys.modules, "execution.control", Control)
    monkeypatch.setattr(execution, "control", Control, raising=False)
    return events, release


async def test_a_second_stop_is_not_held_behind_the_first_ones_bookkeeping(operator, fleet, monkeypatch):
    """A stop's bookkeeping (control.stop, in a thread) takes seconds for a large fleet; the page's next frame, a
    second STOP, gets its zeros out meanwhile. (It waited: whole stop trials of bench.cluster reached their first
    robot seconds late.) Any other command waits for the stops before it: a stop never cancels what came after."""
    from execution import fast_stop

    events, release = _slow_bookkeeping(monkeypatch)
    turtlebot = fleet["turtlebot"]
    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    await fast_stop.TARGETS._load()
    await communicator.send_json_to({"command": "stop", "robots": [turtlebot.pk], "ref": 1})
    await communicator.send_json_to({"command": "stop", "robots": [turtlebot.pk], "ref": 2})
    for _ in range(100):  # bounded: the second zero leaves from the loop at once
        if events.count("zero") == 2:
            break
        await asyncio.sleep(0.02)
    assert events.count("zero") == 2 and not release.is_set()  # both out, the first bookkeeping still running
    await communicator.send_json_to({"command": "dance", "ref": 3})  # anything else comes after the stops
    assert await communicator.receive_nothing(timeout=0.3)
    release.set()
    replies = [await communicator.receive_json_from(timeout=5) for _ in range(3)]
    assert sorted(r["ref"] for r in replies[:2]) == [1, 2] and all(r["ok"] for r in replies[:2])
    assert replies[2]["ref"] == 3 and "unknown" in replies[2]["detail"]
    await communicator.disconnect()


async def test_a_stop_button_is_not_held_behind_a_typed_stop_being_stored(
    operator, fleet, monkeypatch, seeded_ontology
):
    """A typed "stop turtlebot" gets its zeros out from the loop, then submit stores it (the instruction,
    control.stop: seconds for a large fleet). A STOP pressed meanwhile gets its zero out at once (it waited for
    the typed stop's submit); the typed stop and the STOP are both answered once stored."""
    from execution import fast_stop

    events, release = _slow_bookkeeping(monkeypatch)
    turtlebot = fleet["turtlebot"]
    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    await fast_stop.TARGETS._load()
    await communicator.send_json_to({"command": "instruct", "text": "stop turtlebot", "ref": "typed"})
    for _ in range(250):  # bounded: the typed stop's zero, then its submit reaches control.stop
        if "bookkeeping" in events:
            break
        await asyncio.sleep(0.02)
    assert events[0] == "zero" and "bookkeeping" in events, events  # its head start, then submit's own zero
    typed = events.count("zero")
    await communicator.send_json_to({"command": "stop", "robots": [turtlebot.pk], "ref": "button"})
    for _ in range(100):  # bounded: the STOP's zero leaves from the loop at once
        if events.count("zero") > typed:
            break
        await asyncio.sleep(0.02)
    assert events.count("zero") > typed and not release.is_set(), events  # out while the typed stop is stored
    release.set()
    refs = set()
    for _ in range(20):  # bounded: both answers (pushes of the instruction may come between)
        reply = await communicator.receive_json_from(timeout=10)
        if reply.get("type") == "command.result":
            assert reply["ok"] is True, reply
            refs.add(reply["ref"])
        if refs == {"typed", "button"}:
            break
    assert refs == {"typed", "button"}
    await communicator.disconnect()


async def test_a_typed_stop_over_the_socket_publishes_zero_before_the_instruction_is_stored(
    operator, fleet, recorded, seeded_ontology
):
    """The console sends typed text over the page socket: a "stop turtlebot" leaves like the STOP button (the zero
    first, from the loop; then submit stores it and control.stop stops again and answers)."""
    from execution import fast_stop

    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    await fast_stop.TARGETS._load()
    await communicator.send_json_to({"command": "instruct", "text": "stop turtlebot", "ref": "t1"})
    reply = await communicator.receive_json_from(timeout=10)
    while reply.get("type") != "command.result":
        reply = await communicator.receive_json_from(timeout=10)
    assert reply["ok"] is True and reply["ref"] == "t1", reply
    assert reply["instruction"]["text"] == "stop turtlebot" and reply["instruction"]["status"] == "succeeded"
    assert recorded[0] == ("published", "/cmd_vel", 0.0) and ("control.stop", ["turtlebot"]) in recorded
    await communicator.disconnect()


async def test_typed_text_is_parsed_once_on_its_way_from_the_socket_to_submit(
    operator, fleet, recorded, seeded_ontology, monkeypatch
):
    """The socket reads the text once (for a stop's head start) and submit takes that reading: a stop and a
    question each parsed one time, the stop's robots looked up one time (execution.instructions.Reading), the
    stop still decided before anything is stored."""
    from execution import fast_stop
    from fleetcore.interpretation import Interpretation
    from interpreter import service

    parsed, parse = [], service.parse
    monkeypatch.setattr(service, "parse", lambda text, grammar: parsed.append(text) or parse(text, grammar))
    looked_up, stop_names = [], Interpretation.stop_names
    monkeypatch.setattr(
        Interpretation,
        "stop_names",
        lambda self, fleet: looked_up.append(self.steps) or stop_names(self, fleet),
    )
    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    await fast_stop.TARGETS._load()
    await sync_to_async(service.store().get_grammar)()  # the grammar a running web process has
    for ref, text in (("s", "stop turtlebot"), ("q", "where is turtlebot")):
        await communicator.send_json_to({"command": "instruct", "text": text, "ref": ref})
        reply = await communicator.receive_json_from(timeout=10)
        while reply.get("type") != "command.result":
            reply = await communicator.receive_json_from(timeout=10)
        assert reply["ok"] is True and reply["instruction"]["status"] == "succeeded", reply
    assert parsed == ["stop turtlebot", "where is turtlebot"]
    assert [[step["action"] for step in steps] for steps in looked_up] == [["stop"]]
    assert recorded[0] == ("published", "/cmd_vel", 0.0)
    await communicator.disconnect()


async def test_a_viewer_stop_publishes_nothing(viewer, fleet, recorded):
    from execution import fast_stop

    communicator = await _connect("/ws/fleet/", viewer)
    await communicator.receive_json_from(timeout=5)
    await fast_stop.TARGETS._load()
    await communicator.send_json_to({"command": "stop", "robots": "all"})
    reply = await communicator.receive_json_from(timeout=5)
    assert reply["ok"] is False and "may not stop" in reply["detail"]
    assert recorded == []
    await communicator.disconnect()


async def test_presses_that_come_together_are_checked_in_one_call(operator, fleet, published, monkeypatch):
    from execution import control

    calls = []
    real = control.teleop_grants

    def teleop_grants(robot_ids, user):
        calls.append(sorted(robot_ids))
        return real(robot_ids, user)

    monkeypatch.setattr(control, "teleop_grants", teleop_grants)
    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    communicator = await _connect("/ws/fleet/", operator)
    await communicator.receive_json_from(timeout=5)
    for robot in (turtlebot, husky):
        await communicator.send_json_to(
            {"command": "teleop", "robot": robot.pk, "linear": 0.1, "ref": robot.name}
        )
    replies = {}
    while len(replies) < 2:
        frame = await communicator.receive_json_from(timeout=5)
        for reply in live.page_messages(frame):  # answered together
            if reply.get("type") == "command.result":
                replies[reply["ref"]] = reply
    assert replies["turtlebot"]["ok"] is True
    assert replies["husky"]["ok"] is False and "no move topic" in replies["husky"]["detail"]
    assert calls == [sorted([turtlebot.pk, husky.pk])]
    await communicator.disconnect()


class FakeFeedLink:
    """A rosbridge link that records subscriptions and lets the test deliver messages on them."""

    def __init__(self):
        self.subs, self.dropped = [], []

    async def subscribe(self, topic, type_, callback, throttle_rate=0, queue_length=0):
        self.subs.append((topic, type_, callback, throttle_rate))
        return topic

    async def unsubscribe(self, sub):
        self.dropped.append(sub)


async def test_a_robot_page_follows_its_scan_and_camera_and_drops_them_when_closed(
    viewer, fleet, monkeypatch
):
    link = FakeFeedLink()

    async def get(url):
        return link

    monkeypatch.setattr("robots.rosbridge.pool.get", get)
    robot = fleet["turtlebot"]
    await sync_to_async(robot.topics.create)(name="/cam/compressed", type="sensor_msgs/CompressedImage")
    await sync_to_async(robot.topics.create)(name="/scan", type="sensor_msgs/LaserScan")
    communicator = await _connect(f"/ws/robots/{robot.pk}/", viewer)
    assert (await communicator.receive_json_from(timeout=5))["type"] == "snapshot"
    for _ in range(100):  # the feeds start once the snapshot is out
        if len(link.subs) == 2:
            break
        await asyncio.sleep(0.05)
    assert sorted((topic, rate) for topic, _type, _cb, rate in link.subs) == [
        ("/cam/compressed", 500),
        ("/scan", 500),
    ]
    callbacks = {topic: callback for topic, _type, callback, _rate in link.subs}
    callbacks["/scan"]({"angle_min": -1.0, "angle_increment": 0.5, "range_min": 0.1, "range_max": 3.5,
                        "ranges": [1.23456, None, 2.0]})  # fmt: skip
    scan = await communicator.receive_json_from(timeout=5)
    assert scan["type"] == "robot.scan" and scan["scan"]["ranges"] == [1.235, None, 2.0]
    callbacks["/cam/compressed"]({"format": "png", "data": "iVBORw0KGgo="})
    frame = await communicator.receive_json_from(timeout=5)
    assert (frame["type"], frame["format"], frame["data"]) == ("robot.camera", "png", "iVBORw0KGgo=")
    await communicator.disconnect()
    assert sorted(link.dropped) == ["/cam/compressed", "/scan"]


async def test_the_dashboard_watches_one_robots_scan_at_a_time(viewer, fleet, monkeypatch):
    link = FakeFeedLink()

    async def get(url):
        return link

    monkeypatch.setattr("robots.rosbridge.pool.get", get)
    for robot in fleet.values():
        await sync_to_async(robot.topics.create)(name="/scan", type="sensor_msgs/LaserScan")
    communicator = await _connect("/ws/fleet/", viewer)
    await communicator.receive_json_from(timeout=5)
    await communicator.send_json_to({"command": "watch", "robot": fleet["turtlebot"].pk})
    await communicator.send_json_to({"command": "watch", "robot": fleet["husky"].pk})
    await communicator.send_json_to({"command": "watch", "robot": "husky"})
    assert "robot" in (await communicator.receive_json_from(timeout=5))["detail"]  # a bad id is answered
    assert len(link.subs) == 2 and link.dropped == [
        "/scan"
    ]  # the first robot's scan was dropped for the second
    await communicator.send_json_to({"command": "watch", "robot": None})
    await communicator.disconnect()
    assert link.dropped == ["/scan", "/scan"]


async def test_page_sockets_take_no_channel_of_their_own(viewer, fleet, monkeypatch):
    """Every push reaches a page through its process's group readers (portal.fanout), which open the channels; a
    second dashboard opens none (a waiting receive per socket, and a task and an asyncio.wait per frame, for
    nothing)."""
    from channels.layers import get_channel_layer

    layer = get_channel_layer()
    opened = []
    real = layer.new_channel

    async def new_channel(*args, **kwargs):
        opened.append(await real(*args, **kwargs))
        return opened[-1]

    monkeypatch.setattr(layer, "new_channel", new_channel)
    first = await _connect("/ws/fleet/", viewer)
    assert (await first.receive_json_from(timeout=5))["type"] == "snapshot"
    await asyncio.sleep(0.3)  # its group readers (events, poses) started
    readers = len(opened)
    second = await _connect("/ws/fleet/", viewer)
    assert (await second.receive_json_from(timeout=5))["type"] == "snapshot"
    await sync_to_async(live.robot_status)(fleet["turtlebot"])
    assert (await second.receive_json_from(timeout=5))["type"] == "robot.status"  # pushes still arrive
    assert readers >= 1 and len(opened) == readers
    await first.disconnect()
    await second.disconnect()


async def test_a_change_made_while_the_snapshot_is_read_reaches_the_page_after_it(viewer, fleet, monkeypatch):
    """The page's groups are joined before its snapshot is read: a change made meanwhile (here, right after the
    read) follows the snapshot. Read first and joined after, it was never sent to that page, which showed the
    snapshot's state until the robot changed again."""
    from portal.consumers import FleetConsumer

    turtlebot, read = fleet["turtlebot"], FleetConsumer.snapshot

    def read_then_change(self):
        snapshot = read(self)
        turtlebot.state = "motion"
        turtlebot.save()
        live.robot_status(turtlebot)  # outside a transaction: sent at once
        return snapshot

    monkeypatch.setattr(FleetConsumer, "snapshot", read_then_change)
    communicator = await _connect("/ws/fleet/", viewer)
    snapshot = await communicator.receive_json_from(timeout=5)
    assert snapshot["type"] == "snapshot"
    assert {robot["name"]: robot["state"] for robot in snapshot["robots"]}["turtlebot"] == "ready"
    [status] = [push for push in await _pushes(communicator, 1) if push["type"] == "robot.status"]
    assert (status["robot"], status["state"]) == ("turtlebot", "motion")
    await communicator.disconnect()
