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
        self.sent.append(json.loads(text_data))


async def test_one_encoding_per_tick_for_every_fleet_socket_and_a_slow_one_gets_the_latest_merged(
    monkeypatch,
):
    encoded = []
    monkeypatch.setattr(
        fanout, "encode", lambda poses: encoded.append(poses) or json.dumps(live.poses(poses))
    )
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


async def test_many_dashboards_of_one_process_make_one_member_of_the_poses_group(viewer, fleet):
    dashboards = [await _connect("/ws/fleet/", viewer) for _ in range(4)]
    for dashboard in dashboards:
        await dashboard.receive_json_from(timeout=5)
    layer = get_channel_layer()

    async def members_of_this_process():  # (a server another test left behind may still be a member)
        members = await layer.connection(layer.consistent_hash(live.POSES_GROUP)).zrange(
            layer._group_key(live.POSES_GROUP), 0, -1
        )
        return [member for member in members if layer.client_prefix in member.decode()]

    for _ in range(50):  # the reader joins in the background of the first connect
        if await members_of_this_process():
            break
        await asyncio.sleep(0.02)
    assert len(await members_of_this_process()) == 1  # the process's fanout, not one member per socket

    batch = [pose(fleet["turtlebot"].pk, 1.5)]
    await layer.group_send(live.POSES_GROUP, live.poses(batch))
    for dashboard in dashboards:
        assert (await dashboard.receive_json_from(timeout=5))["poses"] == batch
    for dashboard in dashboards:
        await dashboard.disconnect()
    assert await members_of_this_process() == []  # the last socket out took the reader out of the group


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
    assert "NaN" not in text and json.loads(text, parse_constant=pytest.fail)["poses"] == [pose(1, 0.5)]
    assert [message["poses"] for message in socket.sent] == [[pose(1, 0.5)]]


async def test_the_page_sockets_and_the_api_refuse_to_write_nan():
    from portal.api import api
    from portal.consumers import AlertsConsumer, FleetConsumer

    for consumer in (FleetConsumer, AlertsConsumer):
        with pytest.raises(ValueError, match="JSON compliant"):
            await consumer.encode_json({"x": float("nan")})
    with pytest.raises(ValueError, match="JSON compliant"):
        api.renderer.render(None, {"x": float("inf")}, response_status=200)
