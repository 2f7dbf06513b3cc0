"""A recording of a simulated robot driven on its cmd_vel: the poses in the file show it moving (as the simulator
moved it), and the raw command topic holds the commands it received."""

import asyncio
import math

import pytest

from recordings import recorder
from recordings.mcapfile import read_messages
from robots.rosbridge import RosbridgeClient
from tests.execution.conftest import turtle_sim, turtle_world  # noqa: F401 (fixtures)
from tests.portal.demo import pose_stream

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]

FORWARD = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
STILL = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


def test_a_recording_of_a_driven_robot_shows_it_moving_and_its_commands(turtle_world, tmp_path):  # noqa: F811
    robot = turtle_world.robots["turtlebot"]
    move = robot.bindings.get(action="move")
    raw = recorder.parse_raw_topics([f"turtlebot:{move.target}"])
    path = tmp_path / "drive.mcap"

    async def scenario():
        ready = asyncio.Event()
        recording = asyncio.create_task(recorder.record(path, 4.0, raw, ready))
        await ready.wait()
        async with RosbridgeClient(robot.endpoint, ping_interval=None) as client:
            for _ in range(15):
                await client.publish(move.target, FORWARD, move.message_type)
                await asyncio.sleep(0.1)
            await client.publish(move.target, STILL, move.message_type)
        return await recording

    with pose_stream():
        counts = asyncio.run(scenario())
    poses = [m.pose.position for topic, _, _, m in read_messages(path) if topic == "/fleet/turtlebot/pose"]
    assert counts["/fleet/turtlebot/pose"] == len(poses) >= 10
    moved = math.hypot(poses[-1].x - poses[0].x, poses[-1].y - poses[0].y)
    assert moved > 0.1  # 0.2 m/s for 1.5 s at twice real time: ~0.6 m
    sent = [m.linear.x for topic, _, _, m in read_messages(path) if topic.startswith("/raw/turtlebot/")]
    assert len(sent) == counts[f"/raw/turtlebot/{move.target.lstrip('/')}"] >= 10
    assert set(sent) <= {0.2, 0.0} and 0.2 in sent
