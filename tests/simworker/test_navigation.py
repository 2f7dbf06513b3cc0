"""Navigation: move_base to A around the crate, cancel, unreachable goals; nav2 navigate_to_pose; latched /map."""

import math

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
    assert tb3.call("/rosapi/action_servers")["values"]["action_servers"] == ["/dock", "/navigate_to_pose"]
    topics = tb3.call("/rosapi/topics")["values"]["topics"]
    assert not [t for t in topics if "/_action/" in t]
    husky = bridge(fast_world.urls["husky"])
    assert husky.call("/rosapi/action_servers")["values"]["action_servers"] == ["/move_base"]
