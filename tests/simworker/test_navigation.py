"""Navigation: move_base to A around the crate, cancel, unreachable goals; nav2 navigate_to_pose; latched /map."""

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fleetcore.world import load_world

pytestmark = pytest.mark.timeout(90)
GOAL_A = {"position": {"x": 2.0, "y": 2.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}


def move_base_goal(goal_id, pose):
    return {
        "goal_id": {"id": goal_id, "stamp": {"secs": 0, "nsecs": 0}},
        "goal": {"target_pose": {"header": {"frame_id": "map"}, "pose": pose}},
    }


def test_move_base_goal_to_a_goes_around_the_crate_active_then_succeeded(fast_world, bridge):
    husky = bridge(fast_world.urls["husky"])
    for topic in ("/move_base/status", "/move_base/result", "/move_base/feedback"):
        husky.send("subscribe", topic=topic, id=f"sub:{topic}")
    start = fast_world.pose("husky")
    husky.send("publish", topic="/move_base/goal", msg=move_base_goal("to-a", GOAL_A))
    statuses, trail = [], []
    while True:
        msg = husky.recv(timeout=30)
        if msg["topic"] == "/move_base/status":
            ours = [s["status"] for s in msg["msg"]["status_list"] if s["goal_id"]["id"] == "to-a"]
            if ours and (not statuses or statuses[-1] != ours[0]):
                statuses.append(ours[0])
        elif msg["topic"] == "/move_base/feedback":
            trail.append(msg["msg"]["feedback"]["base_position"]["pose"]["position"])
        elif msg["topic"] == "/move_base/result":
            assert msg["msg"]["status"]["goal_id"]["id"] == "to-a"
            assert msg["msg"]["status"]["status"] == 3
            break
    assert statuses[0] == 1
    assert math.dist(fast_world.pose("husky")[:2], (2.0, 2.0)) < 0.2
    grid = load_world("paper").map
    straight = [(start[0], start[1] + (2.0 - start[1]) * i / 50) for i in range(51)]
    assert not all(grid.is_free(x, y) for x, y in straight)  # the straight line is blocked by the crate ...
    assert max(abs(p["x"] - start[0]) for p in trail) > 0.5  # ... so the robot went around it


def test_move_base_simple_goal_and_cancel_preempts(fast_world, bridge):
    tiago = bridge(fast_world.urls["tiago"])
    tiago.send("subscribe", topic="/move_base/result", id="r")
    tiago.send(
        "publish",
        topic="/move_base_simple/goal",
        msg={"header": {"frame_id": "map"}, "pose": {"position": {"x": -1.0, "y": 1.0}}},
    )
    tiago.send("publish", topic="/move_base/cancel", msg={"id": "", "stamp": {"secs": 0, "nsecs": 0}})
    result = tiago.wait_for(lambda m: m.get("topic") == "/move_base/result")
    assert result["msg"]["status"]["status"] == 2  # PREEMPTED


def test_unreachable_goal_is_aborted(fast_world, bridge):
    robot = bridge(fast_world.urls["robots"])
    robot.send("subscribe", topic="/robot2/move_base/result", id="r")
    inside_wall = {"position": {"x": 6.05, "y": 0.0}, "orientation": {"w": 1.0}}
    robot.send("publish", topic="/robot2/move_base/goal", msg=move_base_goal("wall", inside_wall))
    result = robot.wait_for(lambda m: m.get("topic") == "/robot2/move_base/result")
    assert result["msg"]["status"]["status"] == 4  # ABORTED


def test_map_is_latched_and_static_map_answers(fast_world, bridge):
    husky = bridge(fast_world.urls["husky"])
    husky.send("subscribe", topic="/map", type="nav_msgs/OccupancyGrid", id="m")
    grid = husky.wait_for(lambda m: m.get("topic") == "/map")["msg"]
    assert (grid["info"]["width"], grid["info"]["height"]) == (260, 260)
    assert len(grid["data"]) == 260 * 260 and set(grid["data"]) == {-1, 0, 100}
    assert husky.call("/static_map")["values"]["map"]["info"]["resolution"] == pytest.approx(0.05)
    husky.send("subscribe", topic="/amcl_pose", id="a")
    pose = husky.wait_for(lambda m: m.get("topic") == "/amcl_pose")["msg"]["pose"]["pose"]["position"]
    assert math.dist((pose["x"], pose["y"]), fast_world.pose("husky")[:2]) < 0.5


def test_nav2_navigate_to_pose_succeeds_with_feedback(fast_world, bridge):
    tb3 = bridge(fast_world.urls["tb3_nav2"])
    target = {
        "header": {"frame_id": "map", "stamp": {"sec": 0, "nanosec": 0}},
        "pose": {"position": {"x": -1.0, "y": -2.5, "z": 0.0}, "orientation": {"w": 1.0}},
    }
    tb3.send(
        "send_action_goal",
        action="/navigate_to_pose",
        action_type="nav2_msgs/action/NavigateToPose",
        id="nav2-1",
        feedback=True,
        args={"pose": target, "behavior_tree": ""},
    )
    feedback = tb3.wait_for(lambda m: m["op"] == "action_feedback")
    assert feedback["id"] == "nav2-1" and feedback["values"]["distance_remaining"] > 0
    assert set(feedback["values"]["navigation_time"]) == {"sec", "nanosec"}
    result = tb3.wait_for(lambda m: m["op"] == "action_result")
    assert (result["status"], result["result"], result["id"]) == (4, True, "nav2-1")
    assert math.dist(fast_world.pose("tb3_nav2")[:2], (-1.0, -2.5)) < 0.2


def test_nav2_cancel_action_goal_cancels(fast_world, bridge):
    tb3 = bridge(fast_world.urls["tb3_nav2"])
    target = {"header": {"frame_id": "map"}, "pose": {"position": {"x": 2.0, "y": -2.0}}}
    tb3.send(
        "send_action_goal",
        action="/navigate_to_pose",
        action_type="nav2_msgs/action/NavigateToPose",
        id="nav2-2",
        args={"pose": target},
    )
    tb3.send("cancel_action_goal", action="/navigate_to_pose", id="nav2-2")
    result = tb3.wait_for(lambda m: m["op"] == "action_result")
    assert (result["status"], result["id"]) == (5, "nav2-2")


def test_nav2_action_servers_are_listed_without_hidden_topics(fast_world, bridge):
    tb3 = bridge(fast_world.urls["tb3_nav2"])
    assert tb3.call("/rosapi/action_servers")["values"]["action_servers"] == [
        "/dock",
        "/navigate_through_poses",
        "/navigate_to_pose",
    ]
    topics = tb3.call("/rosapi/topics")["values"]["topics"]
    assert not [t for t in topics if "/_action/" in t]
    husky = bridge(fast_world.urls["husky"])
    assert husky.call("/rosapi/action_servers")["values"]["action_servers"] == ["/move_base"]


def nav2_pose(x, y):
    return {"header": {"frame_id": "map"}, "pose": {"position": {"x": x, "y": y}, "orientation": {"w": 1.0}}}


def test_nav2_navigate_through_poses_visits_each_pose_with_feedback(fast_world, bridge):
    tb3 = bridge(fast_world.urls["tb3_nav2"])
    x, y, _ = fast_world.pose("tb3_nav2")
    poses = [nav2_pose(x + 0.5, y), nav2_pose(x + 0.5, y + 0.5)]
    tb3.send(
        "send_action_goal",
        action="/navigate_through_poses",
        action_type="nav2_msgs/action/NavigateThroughPoses",
        id="through-1",
        feedback=True,
        args={"poses": poses, "behavior_tree": ""},
    )
    remaining = set()
    while True:
        msg = tb3.recv(timeout=30)
        if msg["op"] == "action_feedback":
            remaining.add(msg["values"]["number_of_poses_remaining"])
        elif msg["op"] == "action_result":
            break
    assert (msg["status"], msg["id"], msg["values"]) == (4, "through-1", {"result": {}})
    assert remaining == {2, 1}  # the first pose was passed on the way
    assert math.dist(fast_world.pose("tb3_nav2")[:2], (x + 0.5, y + 0.5)) < 0.2


def test_nav2_cancel_goal_service_with_a_zero_goal_id_cancels_every_goal(fast_world, bridge):
    """A stop from another connection than the goal's: action_msgs/srv/CancelGoal, zero uuid and stamp."""
    sender, stopper = bridge(fast_world.urls["tb3_nav2"]), bridge(fast_world.urls["tb3_nav2"])
    sender.send("subscribe", topic="/navigate_to_pose/_action/status", id="s")
    x, y, _ = fast_world.pose("tb3_nav2")
    sender.send(
        "send_action_goal",
        action="/navigate_to_pose",
        action_type="nav2_msgs/action/NavigateToPose",
        id="far",
        args={"pose": nav2_pose(x + 2.0, y)},
    )
    sender.wait_for(lambda m: m.get("topic") == "/navigate_to_pose/_action/status")  # accepted, executing
    zero = {"goal_id": {"uuid": [0] * 16}, "stamp": {"sec": 0, "nanosec": 0}}
    reply = stopper.call("/navigate_to_pose/_action/cancel_goal", {"goal_info": zero})["values"]
    assert reply["return_code"] == 0 and len(reply["goals_canceling"]) == 1
    status = sender.wait_for(lambda m: m.get("topic") == "/navigate_to_pose/_action/status")
    assert status["msg"]["status_list"][-1]["status"] == 5  # CANCELED, as every client of the action sees
    result = sender.wait_for(lambda m: m["op"] == "action_result")
    assert (result["status"], result["id"]) == (5, "far")


def peak_speed(client, odom_topic, until_op="action_result", timeout=40.0):
    """The highest forward speed odometry reports until the goal's end (a simulated value, not a timing)."""
    peak = 0.0
    while True:
        msg = client.recv(timeout=timeout)
        if msg.get("topic") == odom_topic:
            peak = max(peak, abs(msg["msg"]["twist"]["twist"]["linear"]["x"]))
        elif msg["op"] == until_op or msg.get("topic", "").endswith("/result"):
            return peak


def test_nav2_speed_limit_caps_the_controller_until_lifted(fast_world, bridge):
    tb3 = bridge(fast_world.urls["tb3_nav2"])
    tb3.send("subscribe", topic="/odom", id="o")
    limit = {"header": {"frame_id": ""}, "percentage": True, "speed_limit": 50.0}
    tb3.send("publish", topic="/speed_limit", msg=limit)
    try:
        x, y, _ = fast_world.pose("tb3_nav2")
        tb3.send(
            "send_action_goal",
            action="/navigate_to_pose",
            action_type="nav2_msgs/action/NavigateToPose",
            id="slow",
            args={"pose": nav2_pose(x + 1.0, y)},
        )
        assert 0.05 < peak_speed(tb3, "/odom") <= 0.5 * 0.22 + 0.01
    finally:
        tb3.send("publish", topic="/speed_limit", msg={**limit, "speed_limit": 0.0})  # 0: no limit
    nav = fast_world.fleet.robots["tb3_nav2"].navigator.nav
    deadline = time.monotonic() + 5.0
    while fast_world.call(lambda: nav.max_speed) != pytest.approx(0.22) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert fast_world.call(lambda: nav.max_speed) == pytest.approx(0.22)


def test_move_base_local_planner_reconfigure_sets_its_top_speed(fast_world, bridge):
    husky = bridge(fast_world.urls["husky"])
    service = "/move_base/DWAPlannerROS/set_parameters"
    before = husky.call(service, {"config": {}})["values"]["config"]["doubles"]
    assert before == [{"name": "max_vel_x", "value": 0.5}]
    husky.send("subscribe", topic="/odometry/filtered", id="o")
    husky.send("subscribe", topic="/move_base/result", id="r")
    config = {"doubles": [{"name": "max_vel_x", "value": 0.2}]}
    assert husky.call(service, {"config": config})["values"]["config"]["doubles"][0]["value"] == 0.2
    try:
        x, y, yaw = fast_world.pose("husky")
        ahead = {
            "position": {"x": x + 1.2 * math.cos(yaw), "y": y + 1.2 * math.sin(yaw)},
            "orientation": {"w": 1.0},
        }
        husky.send("publish", topic="/move_base/goal", msg=move_base_goal("slow", ahead))
        assert 0.05 < peak_speed(husky, "/odometry/filtered") <= 0.21
    finally:
        husky.call(service, {"config": {"doubles": before}})
    assert (
        husky.call(service, {"config": {"doubles": [{"name": "max_vel_x", "value": "fast"}]}})["result"]
        is False
    )


def test_roslibpy_action_client_runs_and_cancels_nav2_goals(fast_world):
    """roslibpy's ROS 2 ActionClient (a real client, in its own process): navigate_through_poses with feedback to
    SUCCEEDED, and a navigate_to_pose goal cancelled after its third feedback ends CANCELED."""
    x, y, _ = fast_world.pose("tb3_nav2")
    script = Path(__file__).with_name("roslibpy_nav2.py")
    args = [sys.executable, str(script), fast_world.urls["tb3_nav2"], str(x), str(y)]
    out = subprocess.run(args, capture_output=True, text=True, timeout=80, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout)
    through, cancelled = seen["through"], seen["cancelled"]
    assert through["feedback"] > 0 and "number_of_poses_remaining" in through["last_feedback"]
    assert through["result"]["status"] == 4, through
    assert cancelled["result"]["status"] == 5, cancelled
    assert (
        math.dist(fast_world.pose("tb3_nav2")[:2], (x + 0.4, y + 0.4)) < 0.5
    )  # it stopped near where it was
