"""roslibpy, a real rosbridge client, discovers and drives every demo endpoint of the paper world.

roslibpy runs in a subprocess (tests/simworker/roslibpy_probe.py, asyncio transport): its transports are
process-wide, and this pytest process may already be tied to Twisted by daphne.
"""

import itertools
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from fleetcore.catalog import model
from simworker.testing import running_world

PROBE = Path(__file__).with_name("roslibpy_probe.py")
CASES = {
    # endpoint: (robot, model, command topic, odometry topic, robot_description param, speed m/s, ROS version)
    "robots": ("robot1", "turtlebot3_burger", "/robot1/cmd_vel", "/robot1/odom", "/robot1/robot_description", 0.2, 1),
    "turtlebot": ("turtlebot", "turtlebot3_burger", "/cmd_vel", "/odom", "/robot_description", 0.2, 1),
    "husky": ("husky", "husky", "/husky_velocity_controller/cmd_vel", "/odometry/filtered", "/robot_description", 0.5, 1),
    "tiago": ("tiago", "tiago", "/mobile_base_controller/cmd_vel", "/mobile_base_controller/odom",
              "/robot_description", 0.5, 1),
    "spot": ("spot", "spot", "/spot/cmd_vel", "/spot/odometry", "/robot_description", 0.4, 1),
    "tb3_nav2": ("tb3_nav2", "turtlebot3_burger", "/cmd_vel", "/odom", "/robot_state_publisher:robot_description", 0.2, 2),
}  # fmt: skip
pytestmark = pytest.mark.timeout(90)


@pytest.fixture(scope="module")
def probed():
    """Run the paper world, let roslibpy probe every endpoint at once; return (results, start and end poses)."""
    with running_world("paper") as sim:
        cases = []
        for key, (_robot, _model, cmd, odom, param, speed, ros) in CASES.items():
            odom_type = "nav_msgs/Odometry" if ros == 1 else "nav_msgs/msg/Odometry"
            cases.append(
                {
                    "url": sim.urls[key],
                    "cmd": cmd,
                    "odom": odom,
                    "odom_msg_type": odom_type,
                    "param": param,
                    "speed": speed,
                }
            )
        before = {key: sim.pose(c[0]) for key, c in CASES.items()}
        out = subprocess.run(
            [sys.executable, str(PROBE), json.dumps(cases)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        after = {key: sim.pose(c[0]) for key, c in CASES.items()}
    assert out.returncode == 0, out.stderr[-2000:]
    return dict(zip(CASES, json.loads(out.stdout), strict=True)), before, after


@pytest.mark.parametrize("key", CASES)
def test_roslibpy_lists_topics_nodes_services_and_types(probed, key):
    result = probed[0][key]
    assert "error" not in result, result.get("error")
    _robot, _model, cmd, odom, _param, _speed, ros = CASES[key]
    assert {cmd, odom, "/client_count", "/connected_clients", "/rosout"} <= set(result["topics"])
    assert {"/rosapi", "/rosbridge_websocket"} <= set(result["nodes"])
    assert {"/rosapi/topics", "/rosapi/get_param", "/rosapi/nodes"} <= set(result["services"])
    assert result["cmd_type"] == ("geometry_msgs/Twist" if ros == 1 else "geometry_msgs/msg/Twist")
    assert result["odom_type"] == ("nav_msgs/Odometry" if ros == 1 else "nav_msgs/msg/Odometry")
    assert set(result["node_details"]) == {"subscribing", "publishing", "services"}
    if ros == 1:
        assert "/rosbridge_websocket/get_loggers" in result["services"] and "/rosout_agg" in result["topics"]
    else:
        assert "/rosapi/get_ros_version" in result["services"]


@pytest.mark.parametrize("key", CASES)
def test_robot_description_names_the_models_joints(probed, key):
    result = probed[0][key]
    description = result["description"]
    assert description.startswith("<?xml") and 'link name="base_footprint"' in description
    for joint in model(CASES[key][1]).joints:
        assert f'joint name="{joint}"' in description
    assert CASES[key][4] in result["params"]


def _stamp(msg):
    s = msg["header"]["stamp"]
    return s.get("secs", s.get("sec")) + s.get("nsecs", s.get("nanosec", 0)) * 1e-9


@pytest.mark.parametrize("key", CASES)
def test_twist_moves_the_robot_at_the_commanded_speed_within_the_acceleration_limit(probed, key):
    results, before, after = probed
    odom = results[key]["odom"]
    _robot, model_key, *_rest, speed, _ros = CASES[key]
    profile = model(model_key)
    assert len(odom) > 20
    speeds = [m["twist"]["twist"]["linear"]["x"] for m in odom]
    assert max(speeds) == pytest.approx(speed, abs=0.01)
    assert all(v <= speed + 0.01 for v in speeds)
    for a, b in itertools.pairwise(odom):
        dt = _stamp(b) - _stamp(a)
        dv = abs(b["twist"]["twist"]["linear"]["x"] - a["twist"]["twist"]["linear"]["x"])
        assert dv <= profile.acc_v * dt + 0.02
    assert speeds[-1] == pytest.approx(0.0, abs=1e-3)  # stopped after the command timed out
    travelled = odom[-1]["pose"]["pose"]["position"]["x"]
    assert travelled > 0.5 * speed * 1.5
    assert math.dist(before[key][:2], after[key][:2]) == pytest.approx(travelled, abs=0.03)
