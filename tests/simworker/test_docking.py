"""tb3_nav2's dock: the irobot_create_msgs/action/Dock server at /dock, driven through the portal's own rosbridge
client as the executor drives it, and judged by the robot's odometry and ground-truth pose.
"""

import asyncio
import dataclasses
import itertools
import math

import pytest

from fleetcore.catalog import model
from fleetcore.geometry import compose, distance, pose_of, twist_of, wrap
from fleetcore.world import load_world
from robots.rosbridge.client import RosbridgeClient
from robots.rosbridge.errors import ServiceError
from simworker.testing import running_world

pytestmark = [pytest.mark.timeout(90), pytest.mark.asyncio]

DOCK_ACTION, DOCK_TYPE = "/dock", "irobot_create_msgs/action/Dock"
NAV_ACTION, NAV_TYPE = "/navigate_to_pose", "nav2_msgs/action/NavigateToPose"
ODOM_TYPE = "nav_msgs/msg/Odometry"
SPEC = next(r for r in load_world("paper").robots if r.name == "tb3_nav2")
START, DOCK = (SPEC.x, SPEC.y, SPEC.yaw), SPEC.dock
MAX_V = model(SPEC.model).max_v
RESULT_S = 60.0  # wall seconds for one goal at 8x real time (a drive across the room takes < 10)


@pytest.fixture
def sim():
    """Only the tb3_nav2 endpoint of the paper world, at 8x real time, fresh for every test."""
    with running_world("paper", endpoints=["tb3_nav2"], time_scale=8.0) as world:
        yield world


def nav_goal(x: float, y: float) -> dict:
    return {"pose": {"header": {"frame_id": "map"}, "pose": {"position": {"x": x, "y": y}}}}


def on_map(odometry: dict) -> tuple[float, float, float]:
    """The odometry's pose on the map: odom starts at the robot's start pose (its spawn pose)."""
    return compose(START, pose_of(odometry))


def stamp(odometry: dict) -> float:
    t = odometry["header"]["stamp"]
    return t["sec"] + t["nanosec"] * 1e-9


async def until(predicate, limit: float = 30.0) -> None:
    """Wait (bounded) until predicate() holds."""
    for _ in range(int(limit / 0.02)):
        if predicate():
            return
        await asyncio.sleep(0.02)
    raise AssertionError("condition not reached")


async def test_dock_drives_the_robot_across_the_room_onto_its_dock(sim):
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        away = await client.send_action_goal(NAV_ACTION, NAV_TYPE, nav_goal(-1.0, -2.5))
        assert (await away.wait(RESULT_S))["status"] == 4
        trail, feedback = [], []
        await client.subscribe("/odom", ODOM_TYPE, trail.append)
        goal = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {}, on_feedback=feedback.append)
        result = await goal.wait(RESULT_S)
    assert result == {"status": 4, "values": {"is_docked": True}}
    poses = [on_map(m) for m in trail]
    assert distance(poses[0], DOCK) > 2.0  # it set off from the far side of the room ...
    assert distance(poses[-1], DOCK) < 0.1 and abs(wrap(poses[-1][2] - DOCK[2])) < 0.1  # ... odometry: docked
    truth = sim.pose("tb3_nav2")
    assert distance(truth, DOCK) < 0.1 and abs(wrap(truth[2] - DOCK[2])) < 0.1  # the body is on its dock
    steps = [distance(a, b) for a, b in itertools.pairwise(poses)]
    assert max(steps) < 0.05  # never a jump: at most max_v per odometry period (0.011 m) and some slack
    travelled = sum(steps)
    assert travelled > 2.0
    assert stamp(trail[-1]) - stamp(trail[0]) >= travelled / MAX_V  # it took the time its speed limit needs
    assert feedback[0] == {"sees_dock": False} and feedback[-1] == {"sees_dock": True}


async def test_docked_robot_sees_its_station_by_laser_and_dock_status(sim):
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        statuses, scans = [], []
        await client.subscribe("/dock_status", "irobot_create_msgs/msg/DockStatus", statuses.append)
        await until(lambda: statuses)
        assert (statuses[-1]["dock_visible"], statuses[-1]["is_docked"]) == (False, False)  # facing away
        goal = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
        assert (await goal.wait(RESULT_S))["values"] == {"is_docked": True}
        seen = len(statuses)
        await until(lambda: len(statuses) > seen)
        await client.subscribe("/scan", "sensor_msgs/msg/LaserScan", scans.append)
        await until(lambda: scans)
    assert (statuses[-1]["dock_visible"], statuses[-1]["is_docked"]) == (True, True)
    ahead = scans[-1]["ranges"][0]  # the ray straight ahead: the station, not the wall 0.9 m away
    assert ahead is not None and ahead < 0.25


async def test_a_dock_goal_cancels_navigation_and_a_navigate_goal_cancels_docking(sim):
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        nav = await client.send_action_goal(NAV_ACTION, NAV_TYPE, nav_goal(2.0, -2.0))
        await until(lambda: distance(sim.pose("tb3_nav2"), START) > 0.3)
        dock = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
        assert (await nav.wait(10))["status"] == 5  # the navigate goal ended CANCELED
        mark = sim.pose("tb3_nav2")
        await until(lambda: distance(sim.pose("tb3_nav2"), mark) > 0.2)  # docking drives it now
        back = await client.send_action_goal(NAV_ACTION, NAV_TYPE, nav_goal(-1.0, -3.0))
        assert await dock.wait(10) == {"status": 5, "values": {"is_docked": False}}
        assert (await back.wait(RESULT_S))["status"] == 4  # and the navigator has the base to itself again
    assert distance(sim.pose("tb3_nav2"), (-1.0, -3.0)) < 0.2


async def test_cancel_stops_the_robot_short_of_its_dock(sim):
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        goal = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
        await until(
            lambda: distance(sim.pose("tb3_nav2"), DOCK) < 0.4
        )  # turned round, creeping onto the dock
        await client.cancel_action_goal(goal)
        assert await goal.wait(10) == {"status": 5, "values": {"is_docked": False}}
        trail = []
        await client.subscribe("/odom", ODOM_TYPE, trail.append)
        await until(lambda: len(trail) >= 20)  # one simulated second of odometry
    poses = [on_map(m) for m in trail]
    assert max(distance(poses[0], p) for p in poses) < 0.005  # standing still ...
    assert twist_of(trail[-1]) == (0.0, 0.0)
    assert distance(poses[-1], DOCK) > 0.05  # ... short of the dock


async def test_a_blocked_approach_is_aborted_and_the_robot_stops(sim):
    # A box the map does not show, on the line between the staging point and the dock (a person's bag).
    x, y, yaw = DOCK
    sim.call(sim.fleet.physics.add_fixture, x - 0.3 * math.cos(yaw), y - 0.3 * math.sin(yaw), yaw, 0.05, 0.3)
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        goal = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
        assert await goal.wait(RESULT_S) == {"status": 6, "values": {"is_docked": False}}
        trail = []
        await client.subscribe("/odom", ODOM_TYPE, trail.append)
        await until(lambda: len(trail) >= 20)
    assert twist_of(trail[-1]) == (0.0, 0.0)
    assert distance(sim.pose("tb3_nav2"), DOCK) > 0.2


async def test_an_unreachable_dock_is_aborted():
    world = load_world("paper")
    # Facing away from the wall 0.3 m behind it: the staging point in front of the station is inside the wall.
    world.robots = [
        dataclasses.replace(r, dock=(-1.0, -5.75, math.pi / 2)) if r.name == "tb3_nav2" else r
        for r in world.robots
    ]
    with running_world(world, endpoints=["tb3_nav2"], time_scale=8.0) as sim:
        async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
            goal = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
            assert await goal.wait(RESULT_S) == {"status": 6, "values": {"is_docked": False}}
        assert distance(sim.pose("tb3_nav2"), START) < 0.01


async def test_docking_when_docked_succeeds_at_once_and_a_goal_with_fields_is_refused(sim):
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        first = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
        assert (await first.wait(RESULT_S))["status"] == 4
        docked = sim.pose("tb3_nav2")
        again = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {})
        assert await again.wait(5) == {"status": 4, "values": {"is_docked": True}}
        assert distance(sim.pose("tb3_nav2"), docked) < 0.005
        bad = await client.send_action_goal(DOCK_ACTION, DOCK_TYPE, {"dock_id": 1})
        with pytest.raises(ServiceError, match="Invalid goal"):
            await bad.wait(5)


async def test_rosapi_lists_the_dock_action_server_with_its_type(sim):
    async with RosbridgeClient(sim.urls["tb3_nav2"]) as client:
        servers = await client.call_service("/rosapi/action_servers")
        feedback = await client.call_service("/rosapi/topic_type", {"topic": "/dock/_action/feedback"})
        status = await client.call_service("/rosapi/topic_type", {"topic": "/dock_status"})
    assert servers["action_servers"] == ["/dock", "/navigate_through_poses", "/navigate_to_pose"]
    assert feedback["type"] == "irobot_create_msgs/action/Dock_FeedbackMessage"
    assert status["type"] == "irobot_create_msgs/msg/DockStatus"
