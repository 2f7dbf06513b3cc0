"""portal.fanout: one reader of the pose ticks per web process, one encoding per tick for all its fleet sockets,
and a slow socket caught up with the latest pose of each robot it missed, never holding the others back."""

import asyncio
import json

import pytest
from channels.layers import get_channel_layer

import live
from portal import fanout
from tests.portal.test_websockets import _connect

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.asyncio, pytest.mark.timeout(30)]


def pose(robot_id: int, x: float) -> dict:
    return {"id": robot_id, "x": x, "y": 0.0, "yaw": 0.0}


class Socket:
    """A consumer's send, held by an event when `slow` (a client that does not read)."""

    def __init__(self, slow: bool = False) -> None:
        self.sent: list[dict] = []
        self.gate = asyncio.Event()
        if not slow:
            self.gate.set()

    async def send(self, text_data: str) -> None:
        await self.gate.wait()
        message = json.loads(text_data)
        self.sent.append({**message, "poses": fanout.decode(message)})


async def test_one_encoding_per_tick_for_every_fleet_socket_and_a_slow_one_gets_the_latest_merged(
    monkeypatch,
):
    encoded, encode = [], fanout.encode
    monkeypatch.setattr(fanout, "encode", lambda poses: encoded.append(poses) or encode(poses))
    hub = fanout.PoseFanout(layer=None)
    fast = [Socket() for _ in range(3)]
    slow, page = Socket(slow=True), Socket()
    for socket in fast:
        hub.sockets[socket] = fanout._Socket(socket, None)
    hub.sockets[slow] = fanout._Socket(slow, None)
    hub.sockets[page] = fanout._Socket(page, 2)  # a robot page: robot 2 only

    ticks = [[pose(1, 0.1), pose(2, 0.1)], [pose(1, 0.2)], [pose(1, 0.3), pose(2, 0.3)]]
    for tick in ticks:
        hub.deliver(tick)
        await asyncio.sleep(0.01)
    for socket in fast:
        assert [message["poses"] for message in socket.sent] == ticks
    assert [message["poses"] for message in page.sent] == [[pose(2, 0.1)], [pose(2, 0.3)]]
    # the fleet sockets shared one encoding per tick; the page's were its own (one robot each)
    assert encoded.count(ticks[0]) == 1 and encoded.count(ticks[2]) == 1

    assert slow.sent == []  # still sending the first tick: the others did not wait for it
    slow.gate.set()
    await asyncio.sleep(0.01)
    assert [message["poses"] for message in slow.sent] == [ticks[0], [pose(1, 0.3), pose(2, 0.3)]]


async def test_ticks_read_together_are_encoded_once_each_for_every_socket(monkeypatch):
    """A busy web process reads two ticks before its sockets' sends of the first have run: each socket then gets
    the second tick's shared text, not an encoding of its own."""
    encoded, encode = [], fanout.encode
    monkeypatch.setattr(fanout, "encode", lambda poses: encoded.append(poses) or encode(poses))
    hub = fanout.PoseFanout(layer=None)
    sockets = [Socket() for _ in range(25)]
    for socket in sockets:
        hub.sockets[socket] = fanout._Socket(socket, None)
    first, second = [pose(1, 0.1), pose(2, 0.1)], [pose(1, 0.2), pose(2, 0.2)]
    hub.deliver(first)
    hub.deliver(second)  # in the same turn of the loop: no socket has been sent the first yet
    await asyncio.sleep(0.01)
    for socket in sockets:
        assert [message["poses"] for message in socket.sent] == [first, second]
    assert encoded == [first, second]


async def members_of_this_process(group: str) -> list[str]:
    """This event loop's members of a channel-layer group: the channels its subscription to the group feeds (the
    pub/sub layer subscribes a loop to a group once, whatever its members)."""
    layer = get_channel_layer()._get_layer()  # this loop's (channels_redis.pubsub)
    return sorted(layer.groups.get(layer._get_group_channel_name(group), ()))


async def one_member_of(group: str) -> bool:
    """Whether this process joined the group with one member only (its reader joins in the background of the
    first connect)."""
    for _ in range(50):
        if await members_of_this_process(group):
            break
        await asyncio.sleep(0.02)
    return len(await members_of_this_process(group)) == 1


async def test_many_dashboards_of_one_process_make_one_member_of_the_poses_group(viewer, fleet):
    dashboards = [await _connect("/ws/fleet/", viewer) for _ in range(4)]
    for dashboard in dashboards:
        await dashboard.receive_json_from(timeout=5)
    layer = get_channel_layer()
    assert await one_member_of(live.POSES_GROUP)  # the process's fanout, not one member per socket

    batch = [pose(fleet["turtlebot"].pk, 1.5)]
    await layer.group_send(live.POSES_GROUP, live.poses(batch))
    for dashboard in dashboards:
        assert fanout.decode(await dashboard.receive_json_from(timeout=5)) == batch
    for dashboard in dashboards:
        await dashboard.disconnect()
    assert await members_of_this_process(live.POSES_GROUP) == []  # the last one out took the reader out


async def test_a_socket_takes_commands_while_joining_the_poses_group_hangs(viewer, fleet, monkeypatch):
    layer = get_channel_layer()
    joining = asyncio.Event()
    group_add = layer.group_add

    async def hung_for_poses(group, channel):
        if group != live.POSES_GROUP:
            return await group_add(group, channel)
        joining.set()
        await asyncio.Event().wait()  # Redis that never answers, for this call only

    monkeypatch.setattr(layer, "group_add", hung_for_poses)
    dashboard = await _connect("/ws/fleet/", viewer)
    assert (await dashboard.receive_json_from(timeout=5))["type"] == "snapshot"
    await asyncio.wait_for(joining.wait(), 5)
    await dashboard.send_json_to({"command": "stop", "robots": "all", "ref": 9})
    reply = await dashboard.receive_json_from(timeout=5)  # the socket's commands did not wait for the poses
    assert reply["type"] == "command.result" and reply["ref"] == 9
    await asyncio.wait_for(dashboard.disconnect(), fanout.PoseFanout.LEAVE_S + 3)


async def test_a_tick_is_strict_json_and_a_pose_with_nan_is_left_out_not_the_tick():
    """allow_nan=False: a bare NaN would make JSON.parse throw in every browser and freeze every map."""
    hub = fanout.PoseFanout(layer=None)
    socket = Socket()
    hub.sockets[socket] = fanout._Socket(socket, None)
    hub.deliver([pose(1, 0.5), pose(2, float("nan")), pose(3, float("inf"))])
    await asyncio.sleep(0.01)
    text = fanout.encode([pose(1, 0.5), pose(2, float("nan"))])
    assert "NaN" not in text and fanout.decode(json.loads(text, parse_constant=pytest.fail)) == [pose(1, 0.5)]
    assert [message["poses"] for message in socket.sent] == [[pose(1, 0.5)]]


async def test_the_page_sockets_and_the_api_never_write_nan():
    """The page sockets write NaN and infinity as null (fleetcore.jsontext.dumps: the push goes, saying "not
    known"); the API refuses them."""
    from portal.api import api
    from portal.consumers import AlertsConsumer, FleetConsumer

    for consumer in (FleetConsumer, AlertsConsumer):
        text = await consumer.encode_json({"x": float("nan"), "y": float("-inf"), "z": 1.5})
        assert json.loads(text, parse_constant=pytest.fail) == {"x": None, "y": None, "z": 1.5}
    with pytest.raises(ValueError, match="JSON compliant"):
        api.renderer.render(None, {"x": float("inf")}, response_status=200)


class Consumer:
    """A page consumer's dispatch and close, the dispatch held by an event when `slow`."""

    def __init__(self, slow: bool = False) -> None:
        self.got: list[dict] = []
        self.closed: int | None = None
        self.gate = asyncio.Event()
        if not slow:
            self.gate.set()

    async def dispatch(self, message: dict) -> None:
        await self.gate.wait()
        self.got.append(message)

    async def dispatch_many(self, messages: list[dict]) -> None:  # (a page consumer's: one frame of them)
        for message in messages:
            await self.dispatch(message)

    async def close(self, code: int) -> None:
        self.closed = code


async def gathered() -> None:
    """Past an event fanout's gathering window, and its sends."""
    await asyncio.sleep(fanout.EventFanout.GATHER_S + 0.01)


def status(robot_id: int) -> dict:
    return {"type": "robot.status", "id": robot_id}


async def test_events_wait_for_the_snapshot_come_in_order_and_a_slow_socket_holds_nobody_back():
    hub = fanout.EventFanout(layer=None, group=live.FLEET_GROUP)
    fast, slow, new = Consumer(), Consumer(slow=True), Consumer()
    for consumer in (fast, slow):
        hub.sockets[consumer] = fanout._Queue(consumer)
        hub.release(consumer)
    hub.sockets[new] = fanout._Queue(new)  # subscribed; its snapshot is being sent

    for robot_id in (1, 2, 3):
        hub.take(status(robot_id))
    await gathered()
    assert [m["id"] for m in fast.got] == [1, 2, 3]
    assert slow.got == [] and new.got == []  # the slow one is stuck on its first; the new one is held
    hub.release(new)  # its snapshot is out: what came meanwhile follows, in order
    slow.gate.set()
    await gathered()
    assert [m["id"] for m in new.got] == [1, 2, 3] and [m["id"] for m in slow.got] == [1, 2, 3]


async def test_a_socket_too_far_behind_is_closed_so_that_its_page_starts_again_from_a_snapshot(monkeypatch):
    monkeypatch.setattr(fanout.EventFanout, "BACKLOG", 3)
    hub = fanout.EventFanout(layer=None, group=live.FLEET_GROUP)
    fast, stuck = Consumer(), Consumer(slow=True)
    for consumer in (fast, stuck):
        hub.sockets[consumer] = fanout._Queue(consumer)
        hub.release(consumer)
    for robot_id in range(1, 7):
        hub.take(status(robot_id))
        await (
            gathered()
        )  # the fast one is sent each; the stuck one, stuck on its first, is 5 behind at the end
    await gathered()
    assert [m["id"] for m in fast.got] == [1, 2, 3, 4, 5, 6]
    assert stuck.closed == fanout.EventFanout.OVERFLOW_CODE and stuck not in hub.sockets


async def test_many_dashboards_of_one_process_make_one_member_of_the_fleet_group_and_each_gets_its_pushes(
    viewer, fleet
):
    dashboards = [await _connect("/ws/fleet/", viewer) for _ in range(4)]
    for dashboard in dashboards:
        assert (await dashboard.receive_json_from(timeout=5))["type"] == "snapshot"
    layer = get_channel_layer()
    assert await one_member_of(live.FLEET_GROUP)  # the process's reader, not one member per socket

    await layer.group_send(live.FLEET_GROUP, {"type": "robot.status", "id": fleet["turtlebot"].pk})
    for dashboard in dashboards:
        message = await dashboard.receive_json_from(timeout=5)
        assert message == {"type": "robot.status", "id": fleet["turtlebot"].pk}
    for dashboard in dashboards:
        await dashboard.disconnect()
    assert await members_of_this_process(live.FLEET_GROUP) == []  # the last one out took the reader out


class Bursting(Consumer):
    """A consumer that also takes bursts (the page consumers' dispatch_many), recording each as one frame."""

    def __init__(self, slow: bool = False) -> None:
        super().__init__(slow)
        self.frames: list[list[dict]] = []

    async def dispatch(self, message: dict) -> None:
        await super().dispatch(message)
        self.frames.append([message])

    async def dispatch_many(self, messages: list[dict]) -> None:
        await self.gate.wait()
        self.got.extend(messages)
        self.frames.append(messages)


async def test_a_socket_that_fell_behind_gets_the_backlog_in_frames_of_many_in_order(monkeypatch):
    monkeypatch.setattr(fanout.EventFanout, "FRAME_MAX", 30)
    hub = fanout.EventFanout(layer=None, group=live.FLEET_GROUP)
    slow = Bursting(slow=True)
    hub.sockets[slow] = fanout._Queue(slow)
    hub.release(slow)
    for robot_id in range(1, 51):  # a fleet-wide push, all of it come before the socket's turn to send
        hub.take(status(robot_id))
    slow.gate.set()
    await gathered()
    assert [m["id"] for m in slow.got] == list(range(1, 51))
    assert [len(frame) for frame in slow.frames] == [30, 20]  # frames of FRAME_MAX at most
    hub.take(status(51))
    await gathered()
    assert slow.frames[-1] == [status(51)]  # one push alone: dispatched alone, as always


async def test_the_pushes_that_come_within_the_gathering_window_go_in_one_frame_and_the_next_in_another():
    """A robot's change is several pushes read from Redis one by one (status, transition, task list): each was a
    frame of its own to every page socket, and a dashboard was sent two frames of them for every tick."""
    hub = fanout.EventFanout(layer=None, group=live.FLEET_GROUP)
    page = Bursting()
    hub.sockets[page] = fanout._Queue(page)
    hub.release(page)
    for robot_id in (1, 2, 3):
        hub.take(status(robot_id))
        await asyncio.sleep(hub.GATHER_S / 10)
    assert page.frames == []  # the first has waited less than GATHER_S
    await gathered()
    hub.take(status(4))
    await gathered()
    assert page.frames == [[status(1), status(2), status(3)], [status(4)]]


async def test_a_page_consumer_sends_a_burst_as_one_batch_frame_and_a_bad_push_costs_only_itself():
    from portal.consumers import FleetConsumer

    consumer = FleetConsumer()
    sent = []

    async def base_send(message):  # what the consumer hands to the server (channels' AsyncConsumer.send)
        sent.append(json.loads(message["text"]))

    consumer.base_send = base_send
    pushes = [status(1), {"type": "no.such.handler"}, status(2)]
    await consumer.dispatch_many(pushes)
    assert sent == [{"type": "batch", "messages": [status(1), status(2)]}]
    await consumer.send_json(status(3))  # outside a burst: a frame of its own, as always
    assert sent[-1] == status(3)


async def test_a_socket_gone_under_its_pushes_is_dropped_quietly_and_the_others_go_on(caplog):
    class Gone(Consumer):
        async def dispatch(self, message: dict) -> None:
            raise ConnectionResetError("the client went away")  # as uvicorn's ClientDisconnected (an OSError)

    hub = fanout.EventFanout(layer=None, group=live.FLEET_GROUP)
    gone, fine = Gone(), Consumer()
    for consumer in (gone, fine):
        hub.sockets[consumer] = fanout._Queue(consumer)
        hub.release(consumer)
    for robot_id in (1, 2, 3):
        hub.take(status(robot_id))
    await gathered()
    assert [m["id"] for m in fine.got] == [1, 2, 3]
    assert not hub.sockets[gone].pending and "Traceback" not in caplog.text


async def test_pushes_sent_together_reach_a_dashboard_each_in_their_order(viewer, fleet):
    """A block's pushes to a group go as one channel-layer message (live.together); the process's reader
    unpacks it, and the page gets every push, in order, as if each had come on its own."""
    from asgiref.sync import sync_to_async

    dashboard = await _connect("/ws/fleet/", viewer)
    assert (await dashboard.receive_json_from(timeout=5))["type"] == "snapshot"
    assert await one_member_of(live.FLEET_GROUP)
    robots = [fleet[name] for name in ("turtlebot", "husky", "turtlebot", "husky")]
    states = ["idle", "stopped", "stopped", "idle"]

    def stop_like() -> None:
        with live.together():
            for robot, state in zip(robots, states, strict=True):
                robot.state = state
                live.robot_status(robot)

    await sync_to_async(stop_like, thread_sensitive=False)()
    got = []
    while len(got) < len(robots):
        frame = await dashboard.receive_json_from(timeout=5)
        for message in live.page_messages(frame):
            if message.get("type") == "robot.status":
                got.append((message["robot"], message["state"]))
    assert got == [(robot.name, state) for robot, state in zip(robots, states, strict=True)]
    await dashboard.disconnect()


async def test_a_group_reader_subscribed_again_sends_its_pages_back_to_a_snapshot():
    """The channel layer's subscription was cut and taken again (fleet.channel_layer): the pushes published in
    between are lost, so each page socket is closed with 1013 and its page reconnects to a fresh snapshot; the
    pose fanout, whose ticks come ten times a second, just goes on."""
    hub = fanout.EventFanout(layer=None, group=live.FLEET_GROUP)
    pages = [Consumer(), Consumer()]
    for page in pages:
        hub.sockets[page] = fanout._Queue(page)
        hub.release(page)
    hub.take(status(1))
    await gathered()
    hub.take({"type": live.RESUBSCRIBED})
    await gathered()
    assert [page.closed for page in pages] == [fanout.EventFanout.OVERFLOW_CODE] * 2 and not hub.sockets
    assert [[m["id"] for m in page.got] for page in pages] == [
        [1],
        [1],
    ]  # nothing after it was sent as if whole
    poses = fanout.PoseFanout(layer=None)
    socket = Socket()
    poses.sockets[socket] = fanout._Socket(socket, None)
    poses.take({"type": live.RESUBSCRIBED})
    poses.deliver([pose(1, 0.5)])
    await asyncio.sleep(0.01)
    assert [m["poses"] for m in socket.sent] == [[pose(1, 0.5)]]
