"""Send nav2 goals to a simulated endpoint with roslibpy's ActionClient (a real ROS 2 rosbridge client) and print
what it saw as JSON: navigate_through_poses with feedback to its result, then a navigate_to_pose goal it cancels.

Run in its own process (see roslibpy_probe.py: roslibpy's transports are process-wide).
Usage: python roslibpy_nav2.py <url> <x> <y>
"""

import json
import sys
import threading

import roslibpy


def pose(x: float, y: float) -> dict:
    return {
        "header": {"frame_id": "map"},
        "pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": {"w": 1.0}},
    }


def run_goal(client: roslibpy.ActionClient, goal: dict, cancel_after: float | None = None) -> dict:
    """Send one goal; return its feedback count, last feedback and result (or error)."""
    done, seen = threading.Event(), {"feedback": 0}

    def feedback(values):
        seen["feedback"] += 1
        seen["last_feedback"] = values
        if cancel_after is not None and seen["feedback"] == 3:
            client.cancel_goal(goal_id)

    def result(values):
        seen["result"] = values
        done.set()

    def error(err):
        seen["error"] = str(err)
        done.set()

    goal_id = client.send_goal(roslibpy.Goal(goal), result, feedback, error)
    done.wait(60)
    return seen


def plain(value):
    """What roslibpy hands over, as JSON: its GoalStatus enum as the number, its Messages as dicts."""
    return value.value if hasattr(value, "value") else dict(value)


def main(url: str, x: float, y: float) -> None:
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    ros = roslibpy.Ros(host, int(port), transport="asyncio")
    ros.run(timeout=5)
    try:
        through = roslibpy.ActionClient(
            ros, "/navigate_through_poses", "nav2_msgs/action/NavigateThroughPoses"
        )
        to_pose = roslibpy.ActionClient(ros, "/navigate_to_pose", "nav2_msgs/action/NavigateToPose")
        out = {
            "through": run_goal(
                through, {"poses": [pose(x + 0.4, y), pose(x + 0.4, y + 0.4)], "behavior_tree": ""}
            ),
            "cancelled": run_goal(to_pose, {"pose": pose(x - 2.0, y), "behavior_tree": ""}, cancel_after=3),
        }
    finally:
        ros.terminate()
    print(json.dumps(out, default=plain))


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]), float(sys.argv[3]))
