"""The nav-stack interfaces on top of the Navigator: ROS 1 move_base (+ amcl, map_server) and ROS 2 nav2."""

from __future__ import annotations

import json
import time

from fleetcore.geometry import pose_msg, yaw_of
from fleetcore.planning import Planner
from simworker.graph import ServiceError
from simworker.navigation import ABORTED, ACTIVE, PREEMPTED, SUCCEEDED, Navigator
from simworker.robot import SimRobot, number
from simworker.server import ActionGoal

NAV2_STATUS = {SUCCEEDED: 4, ABORTED: 6, PREEMPTED: 5}  # actionlib -> action_msgs/GoalStatus
STATUS_KEEP = 10


def pose_of(msg: dict) -> tuple[float, float, float | None]:
    """Return (x, y, yaw) of a geometry_msgs/Pose dict; yaw None if no orientation was given."""
    if not isinstance(msg, dict):
        raise TypeError("pose must be an object")
    pos = msg.get("position", {})
    if not isinstance(pos, dict):
        raise TypeError("position must be an object")
    ori = msg.get("orientation")
    yaw = yaw_of(ori) if isinstance(ori, dict) and any(ori.get(k) for k in ("x", "y", "z")) else None
    return number(pos.get("x", 0.0)), number(pos.get("y", 0.0)), yaw


class NavStack:
    """Common part: amcl_pose, /map, /initialpose, the map services, the navigator."""

    def __init__(self, robot: SimRobot, planner: Planner) -> None:
        self.robot = robot
        self.nav = Navigator(robot, planner)
        self.ns = robot.ns
        g = robot.graph
        self.map_msg = planner.grid.to_msg(g.ros_version)
        robot.server.publish_text(f"{self.ns}/map", json.dumps(self.map_msg, separators=(",", ":")))
        g.on_topic(f"{self.ns}/initialpose", self._initialpose)
        static = f"{self.ns}/static_map" if g.ros_version == 1 else f"{self.ns}/map_server/map"
        if static in g.service_types:
            g.service_handlers[static] = lambda _a: {"map": self.map_msg}

    def _initialpose(self, msg: dict) -> None:
        pose_of(msg.get("pose", {}).get("pose", {}))  # validated; amcl converges to the truth anyway
        self.publish_amcl_pose()

    def publish_amcl_pose(self) -> None:
        """Publish the localisation estimate (the ground truth here) on the latched /amcl_pose."""
        x, y, yaw = self.robot.pose()
        cov = [0.0] * 36
        cov[0] = cov[7] = 0.0025
        cov[35] = 0.0007
        self.robot.server.publish(
            f"{self.ns}/amcl_pose",
            {
                "header": self.robot.graph.header("map", self.robot.clock()),
                "pose": {"pose": pose_msg(x, y, yaw), "covariance": cov},
            },
        )

    def tick(self, t: float) -> None:
        self.nav.tick()


class MoveBase(NavStack):
    """ROS 1 move_base action over topics (goal, cancel, status, result, feedback) and move_base_simple."""

    def __init__(self, robot: SimRobot, planner: Planner) -> None:
        super().__init__(robot, planner)
        self.mb = f"{self.ns}/move_base"
        self.statuses: list[dict] = []
        self.current: dict | None = None
        self.counter = 0
        g = robot.graph
        g.on_topic(f"{self.mb}/goal", self._goal)
        g.on_topic(f"{self.ns}/move_base_simple/goal", self._simple_goal)
        g.on_topic(f"{self.mb}/cancel", self._cancel)
        g.service_handlers[f"{self.mb}/make_plan"] = self._make_plan

    def _goal(self, msg: dict) -> None:
        goal_id = msg.get("goal_id", {}) or {}
        target = msg["goal"]["target_pose"]
        self._start(pose_of(target["pose"]), str(goal_id.get("id") or ""), goal_id.get("stamp"))

    def _simple_goal(self, msg: dict) -> None:
        self._start(pose_of(msg["pose"]), "", None)

    def _start(self, pose, goal_id: str, stamp) -> None:
        self.counter += 1
        now = self.robot.clock()
        gid = {
            "stamp": stamp or self.robot.graph.stamp(now),
            "id": goal_id or f"{self.mb}-{self.counter}-{now:.3f}",
        }
        if self.current is not None:
            self.nav.stop(PREEMPTED, "This goal was canceled because another goal was received")
        status = {
            "goal_id": gid,
            "status": ACTIVE,
            "text": "This goal has been accepted by the simple action server",
        }
        self.current = status
        self.statuses = [*self.statuses[-STATUS_KEEP:], status]
        self.publish_status()
        self.robot.server.publish(
            f"{self.mb}/current_goal",
            {
                "header": self.robot.graph.header("map", now),
                "pose": pose_msg(pose[0], pose[1], pose[2] or 0.0),
            },
        )
        self.nav.start(*pose, on_done=lambda code, text, s=status: self._done(s, code, text))

    def _done(self, status: dict, code: int, text: str) -> None:
        status["status"], status["text"] = code, text
        if self.current is status:
            self.current = None
        self.robot.server.publish(
            f"{self.mb}/result",
            {
                "header": self.robot.graph.header("map", self.robot.clock()),
                "status": dict(status),
                "result": {},
            },
        )
        self.publish_status()

    def _cancel(self, msg: dict) -> None:
        gid = str(msg.get("id", "") or "")
        if self.current is not None and gid in ("", self.current["goal_id"]["id"]):
            self.nav.stop(PREEMPTED, "Goal canceled")

    def _make_plan(self, args: dict) -> dict:
        try:
            start, goal = pose_of(args["start"]["pose"]), pose_of(args["goal"]["pose"])
        except (KeyError, TypeError) as exc:
            raise ServiceError(f"make_plan: bad request: {exc}") from exc
        path = self.nav.planner.plan(start[:2], goal[:2]) or []
        poses = [{"header": self.robot.graph.header("map"), "pose": pose_msg(x, y, 0.0)} for x, y in path]
        return {"plan": {"header": self.robot.graph.header("map"), "poses": poses}}

    def publish_status(self) -> None:
        self.robot.server.publish(
            f"{self.mb}/status",
            {
                "header": self.robot.graph.header("", self.robot.clock()),
                "status_list": [dict(s) for s in self.statuses],
            },
        )

    def tick(self, t: float) -> None:
        super().tick(t)
        if self.current is not None and self.robot.server.subscribed(f"{self.mb}/feedback"):
            x, y, yaw = self.robot.pose()
            self.robot.server.publish(
                f"{self.mb}/feedback",
                {
                    "header": self.robot.graph.header("map", t),
                    "status": dict(self.current),
                    "feedback": {
                        "base_position": {
                            "header": self.robot.graph.header("map", t),
                            "pose": pose_msg(x, y, yaw),
                        }
                    },
                },
            )

    def slow_tick(self, t: float) -> None:
        """Publish status at 5 Hz as actionlib does (only when someone listens)."""
        if self.robot.server.subscribed(f"{self.mb}/status"):
            self.publish_status()


class Nav2(NavStack):
    """ROS 2 nav2: navigate_to_pose over rosbridge's send_action_goal / cancel_action_goal, and /goal_pose."""

    def __init__(self, robot: SimRobot, planner: Planner) -> None:
        super().__init__(robot, planner)
        self.goal: ActionGoal | None = None
        self.started = 0.0
        self.docking = None  # the robot's DockServer (simworker/docking.py) if it has a dock station
        robot.server.add_action(
            f"{self.ns}/navigate_to_pose", "nav2_msgs/action/NavigateToPose", self._send_goal
        )
        robot.graph.on_topic(f"{self.ns}/goal_pose", lambda msg: self._navigate(pose_of(msg["pose"]), None))

    def _send_goal(self, goal: ActionGoal, args: dict) -> None:
        try:
            pose = pose_of(args["pose"]["pose"])
        except (KeyError, TypeError) as exc:
            goal.finish(f"Invalid goal: {exc}", status=0, ok=False)
            return
        self._navigate(pose, goal)

    def _navigate(self, pose, goal: ActionGoal | None) -> None:
        if self.docking is not None:
            self.docking.preempt()  # one goal drives the base: navigating ends a dock goal as CANCELED
        if self.goal is not None:
            self.nav.stop(PREEMPTED, "preempted")
        self.goal, self.started = goal, time.monotonic()
        if goal is not None:
            goal.on_cancel = lambda: self.nav.stop(PREEMPTED, "canceled")
        self.nav.start(*pose, on_done=lambda code, text, g=goal: self._done(g, code))

    def _done(self, goal: ActionGoal | None, code: int) -> None:
        if goal is self.goal:
            self.goal = None
        if goal is not None:
            goal.finish({"result": {}}, status=NAV2_STATUS.get(code, 6))

    def tick(self, t: float) -> None:
        super().tick(t)
        goal = self.goal
        if goal is None or not goal.want_feedback:
            return
        x, y, yaw = self.robot.pose()
        elapsed = time.monotonic() - self.started
        dist = self.nav.remaining()
        eta = dist / max(self.robot.profile.nav_speed, 1e-3)
        goal.feedback(
            {
                "current_pose": {"header": self.robot.graph.header("map", t), "pose": pose_msg(x, y, yaw)},
                "navigation_time": {"sec": int(elapsed), "nanosec": int((elapsed % 1) * 1e9)},
                "estimated_time_remaining": {"sec": int(eta), "nanosec": int((eta % 1) * 1e9)},
                "number_of_recoveries": 0,
                "distance_remaining": round(dist, 3),
            }
        )

    def slow_tick(self, t: float) -> None:
        pass
