"""Pose streaming: odometry + start pose = map pose, amcl corrects the offset, one batch per tick."""

import asyncio
import itertools
import json
import math

import pytest

from fleetcore.geometry import compose, inverse, pose_of, yaw_of
from robots.poses import PoseHub, stream_endpoint


def odometry(x, y, yaw, v=0.0, w=0.0) -> dict:
    half = yaw / 2
    return {
        "header": {"stamp": {"secs": 1, "nsecs": 0}, "frame_id": "odom"},
        "pose": {"pose": {"position": {"x": x, "y": y, "z": 0}, "orientation": {"x": 0, "y": 0, "z": math.sin(half), "w": math.cos(half)}}},
        "twist": {"twist": {"linear": {"x": v, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": w}}},
    }  # fmt: skip


class Sink:
    """Collects what the hub publishes."""

    def __init__(self):
        self.batches = []

    async def __call__(self, batch):
        self.batches.append(batch)


def test_compose_and_inverse_round_trip():
    a, b = (1.0, 2.0, 0.7), (-0.3, 0.5, -2.0)
    back = compose(inverse(a), compose(a, b))
    assert back == pytest.approx(b, abs=1e-9)
    assert yaw_of({"x": 0, "y": 0, "z": math.sin(0.4), "w": math.cos(0.4)}) == pytest.approx(0.8)


def test_map_pose_is_odometry_composed_with_the_start_pose():
    hub = PoseHub(publish=Sink(), clock=lambda: 5.0)
    hub.track(1, [2.0, -1.0, math.pi / 2])
    hub.on_odometry(1, odometry(1.0, 0.0, 0.0, v=0.2, w=0.1))
    [pose] = hub.take_batch()
    assert (pose["x"], pose["y"], pose["yaw"]) == pytest.approx((2.0, 0.0, round(math.pi / 2, 3)), abs=1e-3)
    assert (pose["v"], pose["w"], pose["t"]) == (0.2, 0.1, 5.0)


def test_bursts_coalesce_to_the_latest_pose_once_per_tick():
    hub = PoseHub(publish=Sink())
    for step in range(50):
        hub.on_odometry(1, odometry(step * 0.01, 0, 0))
        hub.on_odometry(2, odometry(0, step * 0.01, 0))
    batch = hub.take_batch()
    assert [pose["id"] for pose in batch] == [1, 2]
    assert batch[0]["x"] == pytest.approx(0.49)
    assert hub.take_batch() == []  # nothing new since the last tick


def test_amcl_corrects_the_offset_for_later_odometry():
    hub = PoseHub(publish=Sink(), clock=itertools.count(0.0, 1.0).__next__)  # 1 m in 2 s: no jump
    hub.track(1, [0.0, 0.0, 0.0])
    hub.on_odometry(1, odometry(1.0, 0.0, 0.0))
    hub.on_amcl(1, {"pose": {"pose": {"position": {"x": 3.0, "y": 3.0}, "orientation": {"z": 0, "w": 1}}}})
    hub.on_odometry(1, odometry(2.0, 0.0, 0.0))
    [pose] = hub.take_batch()
    assert (pose["x"], pose["y"]) == pytest.approx((4.0, 3.0))


def test_unreadable_messages_are_dropped_not_raised():
    hub = PoseHub(publish=Sink())

    class Robot:
        pk = 3
        start_pose = []
        max_linear = 1.0

        class bindings:
            @staticmethod
            def all():
                class Binding:
                    action, target, message_type = "odometry", "/odom", "nav_msgs/Odometry"

                return [Binding]

    [sub] = hub.subscriptions(Robot)
    assert (sub.topic, sub.throttle_rate, sub.queue_length) == ("/odom", 100, 1)  # the newest each tick
    sub.callback({"pose": "garbage"})
    sub.callback({})
    assert hub.take_batch() == []


def test_rate_is_validated():
    with pytest.raises(ValueError, match="rate_hz"):
        PoseHub(rate_hz=0)


@pytest.mark.asyncio
async def test_run_publishes_batches_until_stopped():
    sink = Sink()
    hub = PoseHub(publish=sink, rate_hz=50)
    stop = asyncio.Event()
    task = asyncio.create_task(hub.run(stop))
    hub.on_odometry(7, odometry(1, 1, 0))
    while not sink.batches:
        await asyncio.sleep(0.01)
    stop.set()
    await asyncio.wait_for(task, 5)
    assert sink.batches[0][0]["id"] == 7


@pytest.mark.asyncio
@pytest.mark.timeout(20)
async def test_stream_endpoint_subscribes_with_throttle_and_feeds_callbacks():
    """A minimal rosbridge server: checks the subscribe op, then publishes one odometry message."""
    import websockets

    seen_ops, got = [], asyncio.Queue()

    async def server(socket):
        seen_ops.append(json.loads(await socket.recv()))
        await socket.send(json.dumps({"op": "publish", "topic": "/odom", "msg": odometry(0.5, 0, 0)}))
        await socket.send("not json")
        await socket.wait_closed()

    hub = PoseHub(publish=Sink())
    async with websockets.serve(server, "127.0.0.1", 0) as ws_server:
        port = ws_server.sockets[0].getsockname()[1]
        from robots.poses import Subscription

        sub = Subscription(1, "/odom", "nav_msgs/Odometry", lambda msg: got.put_nowait(pose_of(msg)), 100)
        stop = asyncio.Event()
        task = asyncio.create_task(stream_endpoint(f"ws://127.0.0.1:{port}", [sub], stop))
        assert (await asyncio.wait_for(got.get(), 5))[0] == pytest.approx(0.5)
        stop.set()
        await asyncio.wait_for(task, 5)
    assert seen_ops[0]["op"] == "subscribe" and seen_ops[0]["throttle_rate"] == 100
    assert seen_ops[0]["type"] == "nav_msgs/Odometry"
    assert hub.take_batch() == []


def test_battery_and_round_trip_ride_along_with_each_pose():
    hub = PoseHub(publish=Sink())
    hub.on_battery(1, {"percentage": 0.42})  # before any pose: kept for the first one
    hub.on_odometry(1, odometry(0, 0, 0))
    hub.on_round_trip([1, 2], 0.0123)
    [pose] = hub.take_batch()
    assert (pose["battery"], pose["rtt"]) == (42.0, 12.3)
    hub.on_battery(1, {"percentage": 87.0})  # some drivers publish percent
    hub.on_battery(1, {"percentage": float("nan")})  # "not measured": ignored
    [pose] = hub.take_batch()
    assert pose["battery"] == 87.0 and pose["x"] == 0.0
    hub.on_odometry(2, odometry(1, 0, 0))
    assert hub.take_batch()[0]["rtt"] == 12.3


def test_odometry_with_nan_flags_the_last_good_pose_and_reports_it_once():
    reported = []
    clock = itertools.count(100.0, 0.1)
    hub = PoseHub(publish=Sink(), clock=clock.__next__, report=reported.append)
    hub.track(1, [0.0, 0.0, 0.0], max_linear=1.0)
    hub.on_odometry(1, odometry(1.0, 0.0, 0.0))
    hub.on_odometry(2, odometry(0.0, 0.0, 0.0))
    asyncio.run(hub.flush())
    for _ in range(3):
        hub.on_odometry(1, odometry(math.nan, 0.0, 0.0))
        hub.on_odometry(2, odometry(0.0, 0.0, 0.0))
    [flagged, other] = hub.take_batch()
    assert (flagged["x"], flagged["fault"]) == (1.0, "x is NaN")  # the last good pose, never the NaN
    assert flagged["fault_since"] == pytest.approx(100.2) and "fault" not in other
    json.dumps([flagged, other], allow_nan=False)  # no number in it is NaN: this would raise
    asyncio.run(hub.flush())
    assert reported == [{1: ("x is NaN", pytest.approx(100.2))}]  # one report, not one per message

    hub.on_odometry(1, odometry(1.0, 0.0, 0.0))
    [pose] = hub.take_batch()
    assert "fault" not in pose
    asyncio.run(hub.flush())
    assert reported[-1] == {1: (None, None)}


def test_an_amcl_pose_does_not_clear_a_refused_odometry_flag():
    """amcl rides on the odometry: while the gate refuses it the flagged last good pose stands (a 1 Hz amcl pose
    once made "how far is robot2 from A" answer from a pose the portal had just called invalid)."""
    hub = PoseHub(publish=Sink(), clock=itertools.count(100.0, 0.1).__next__, report=lambda changes: None)
    hub.track(1, [0.0, 0.0, 0.0], max_linear=1.0)
    hub.on_odometry(1, odometry(1.0, 0.0, 0.0))
    hub.on_odometry(1, odometry(math.nan, 0.0, 0.0))
    hub.on_amcl(1, {"pose": {"pose": {"position": {"x": 3.0, "y": 3.0}, "orientation": {"z": 0, "w": 1}}}})
    [pose] = hub.take_batch()
    assert (pose["x"], pose["fault"]) == (1.0, "x is NaN")
    hub.on_odometry(1, odometry(1.05, 0.0, 0.0))  # good again: it lands where amcl put the robot
    [pose] = hub.take_batch()
    assert "fault" not in pose and (pose["x"], pose["y"]) == pytest.approx((3.05, 3.0))


def test_a_pose_jumping_faster_than_the_robot_is_refused():
    hub = PoseHub(publish=Sink(), clock=itertools.count(100.0, 0.1).__next__, report=lambda changes: None)
    hub.track(1, [0.0, 0.0, 0.0], max_linear=1.0)
    hub.on_odometry(1, odometry(0.0, 0.0, 0.0))
    hub.on_odometry(1, odometry(1000.0, 0.0, 0.0))
    [pose] = hub.take_batch()
    assert pose["x"] == 0.0 and pose["fault"].startswith("jumped 1000.0 m")
