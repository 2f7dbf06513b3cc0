"""The nav-stack interfaces on top of the Navigator: ROS 1 move_base (+ amcl, map_server) and ROS 2 nav2."""

from __future__ import annotations

import base64
import itertools
import json
import math
import os
import time
from dataclasses import dataclass, field

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
        plugin = str(g.params.get(f"{self.mb}/base_local_planner", ""))
        self.planner_ns = f"{self.mb}/{plugin.rsplit('/', 1)[-1]}"
        if f"{self.planner_ns}/set_parameters" in g.service_types:
            g.service_handlers[f"{self.planner_ns}/set_parameters"] = self._reconfigure
            self._publish_config()

    def _reconfigure(self, args: dict) -> dict:
        """dynamic_reconfigure/Reconfigure on the local planner: max_vel_x (m/s) is the top speed it drives at;
        the reply is the whole configuration after the change (an empty request reads it)."""
        config = args.get("config") or {}
        if not isinstance(config, dict):
            raise ServiceError("set_parameters: config must be an object")
        for item in config.get("doubles") or []:
            if not isinstance(item, dict):
                raise ServiceError("set_parameters: a double must be {name, value}")
            if item.get("name") == "max_vel_x":
                try:
                    value = number(item.get("value"))
                except TypeError as exc:
                    raise ServiceError(f"set_parameters: max_vel_x: {exc}") from exc
                if not value > 0:
                    raise ServiceError(f"set_parameters: max_vel_x must be > 0, not {value}")
                self.nav.max_vel_x = value
                self.robot.graph.params[f"{self.planner_ns}/max_vel_x"] = value
        return {"config": self._publish_config()}

    def _publish_config(self) -> dict:
        """The planner's dynamic_reconfigure/Config, also on its latched parameter_updates."""
        config = {
            "bools": [],
            "ints": [],
            "strs": [],
            "doubles": [{"name": "max_vel_x", "value": self.nav.max_vel_x}],
            "groups": [{"name": "Default", "state": True, "id": 0, "parent": 0}],
        }
        self.robot.server.publish(f"{self.planner_ns}/parameter_updates", config)
        return config

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
    """ROS 2 nav2 (humble): bt_navigator's navigate_to_pose and navigate_through_poses over rosbridge's
    send_action_goal / cancel_action_goal, their hidden cancel_goal services (a zero goal id cancels every goal,
    as action_msgs/srv/CancelGoal says), their status topics, /goal_pose (RViz's goals, run as navigate_to_pose
    goals as bt_navigator does), and the controller server's speed_limit topic (nav2_msgs/msg/SpeedLimit)."""

    def __init__(self, robot: SimRobot, planner: Planner) -> None:
        super().__init__(robot, planner)
        self.goal: Nav2Goal | None = None
        self.started = 0.0
        self.docking = None  # the robot's DockServer (simworker/docking.py) if it has a dock station
        self.cancels: list[
            tuple[str, str]
        ] = []  # (action, "client" or "service") of each cancel: what stops are judged by
        self.statuses: dict[str, list[Nav2Goal]] = {}
        self.speed_limits: list[dict] = []  # every SpeedLimit the controller server took
        for action, kind in ((NAVIGATE, "NavigateToPose"), (THROUGH, "NavigateThroughPoses")):
            name = f"{self.ns}/{action}"
            self.statuses[name] = []
            robot.server.add_action(name, f"nav2_msgs/action/{kind}", self._goal_handler(name))
            robot.graph.service_handlers[f"{name}/_action/cancel_goal"] = self._cancel_service(name)
        robot.graph.on_topic(f"{self.ns}/goal_pose", self._goal_pose)
        robot.graph.on_topic(f"{self.ns}/speed_limit", self._speed_limit)

    # ----- goals -----
    def _goal_handler(self, name: str):
        through = name.endswith(THROUGH)

        def handle(goal: ActionGoal, args: dict) -> None:
            try:
                poses = (
                    [pose_of(p["pose"]) for p in args["poses"]]
                    if through
                    else [pose_of(args["pose"]["pose"])]
                )
                if not poses:
                    raise ValueError("no poses")
            except (KeyError, TypeError, ValueError) as exc:
                goal.finish(f"Invalid goal: {exc}", status=0, ok=False)
                return
            self._navigate(Nav2Goal(name, poses, goal))

        return handle

    def _goal_pose(self, msg: dict) -> None:
        """RViz's 2D Goal Pose: bt_navigator sends it to its own navigate_to_pose (no client sees the result)."""
        self._navigate(Nav2Goal(f"{self.ns}/{NAVIGATE}", [pose_of(msg["pose"])], None))

    def _navigate(self, goal: Nav2Goal) -> None:
        if self.docking is not None:
            self.docking.preempt()  # one goal drives the base: navigating ends a dock goal as CANCELED
        if self.goal is not None:
            self.nav.stop(PREEMPTED, "preempted")
        self.goal, self.started, goal.stamp = goal, time.monotonic(), self.robot.clock()
        if goal.handle is not None:
            goal.handle.on_cancel = lambda g=goal: self._cancel(g, "client")
        self._status(goal, EXECUTING)
        self._next(goal)

    def _next(self, goal: Nav2Goal) -> None:
        self.nav.start(*goal.poses[0], on_done=lambda code, _text, g=goal: self._reached(g, code))

    def _reached(self, goal: Nav2Goal, code: int) -> None:
        if code == SUCCEEDED and len(goal.poses) > 1 and goal is self.goal:
            goal.poses.pop(0)
            self._next(goal)
            return
        if goal is self.goal:
            self.goal = None
        status = NAV2_STATUS.get(code, 6)
        self._status(goal, status)
        if goal.handle is not None:
            goal.handle.finish({"result": {}}, status=status)

    def _cancel(self, goal: Nav2Goal, via: str) -> None:
        """Cancel a goal: by its rosbridge client (cancel_action_goal), or through the action's cancel_goal."""
        self.cancels.append((goal.action, via))
        if goal is self.goal:
            self.nav.stop(PREEMPTED, "canceled")

    def _cancel_service(self, name: str):
        """action_msgs/srv/CancelGoal: a zero uuid cancels every goal of the action, else the one named."""

        def cancel(args: dict) -> dict:
            info = args.get("goal_info") or {}
            uuid = _uuid_bytes((info.get("goal_id") or {}).get("uuid"))
            goal = self.goal if self.goal is not None and self.goal.action == name else None
            if goal is None or (any(uuid) and uuid != goal.uuid):
                self.cancels.append(
                    (name, "service")
                )  # asked, with nothing to cancel (a client's cancel came first)
                return {"return_code": 2 if any(uuid) else 1, "goals_canceling": []}  # unknown id; rejected
            self._cancel(goal, "service")
            return {"return_code": 0, "goals_canceling": [goal.info(self.robot.graph)]}

        return cancel

    def _status(self, goal: Nav2Goal, status: int) -> None:
        """Publish the action's action_msgs/msg/GoalStatusArray as its server does on every change."""
        goal.status = status
        kept = [g for g in self.statuses[goal.action] if g is not goal][-STATUS_KEEP:]
        self.statuses[goal.action] = [*kept, goal]
        self.robot.server.publish(
            f"{goal.action}/_action/status",
            {
                "status_list": [
                    {"goal_info": g.info(self.robot.graph), "status": g.status}
                    for g in self.statuses[goal.action]
                ]
            },
        )

    # ----- the controller server's speed limit -----
    def _speed_limit(self, msg: dict) -> None:
        """nav2_msgs/msg/SpeedLimit: a percentage of the controller's top speed, or m/s; 0 is no limit."""
        limit, percentage = number(msg.get("speed_limit", 0.0)), msg.get("percentage", False)
        if not isinstance(percentage, bool):
            raise TypeError("percentage must be a bool")
        self.speed_limits.append({"percentage": percentage, "speed_limit": limit})
        if limit <= 0.0:
            self.nav.speed_cap = None
        else:
            self.nav.speed_cap = self.nav.max_vel_x * limit / 100.0 if percentage else limit

    # ----- feedback -----
    def tick(self, t: float) -> None:
        super().tick(t)
        goal = self.goal
        if goal is None:
            return
        x, y, yaw = self.robot.pose()
        elapsed = time.monotonic() - self.started
        dist = self.nav.remaining() + sum(math.dist(a[:2], b[:2]) for a, b in itertools.pairwise(goal.poses))
        eta = dist / max(self.nav.max_speed, 1e-3)
        feedback = {
            "current_pose": {"header": self.robot.graph.header("map", t), "pose": pose_msg(x, y, yaw)},
            "navigation_time": _duration(elapsed),
            "estimated_time_remaining": _duration(eta),
            "number_of_recoveries": 0,
            "distance_remaining": round(dist, 3),
        }
        if goal.action.endswith(THROUGH):
            feedback["number_of_poses_remaining"] = len(goal.poses)
        if goal.handle is not None and goal.handle.want_feedback:
            goal.handle.feedback(feedback)
        topic = f"{goal.action}/_action/feedback"
        if self.robot.server.subscribed(topic):
            self.robot.server.publish(topic, {"goal_id": {"uuid": goal.uuid}, "feedback": feedback})

    def slow_tick(self, t: float) -> None:
        pass


NAVIGATE, THROUGH = "navigate_to_pose", "navigate_through_poses"
EXECUTING = 2  # action_msgs/msg/GoalStatus


@dataclass(eq=False)
class Nav2Goal:
    """One goal of a nav2 action: what is left of its poses, its rosbridge handle (None for /goal_pose)."""

    action: str
    poses: list
    handle: ActionGoal | None
    uuid: list[int] = field(default_factory=lambda: list(os.urandom(16)))
    stamp: float = 0.0  # when it was accepted, on the robot's clock
    status: int = 1

    def info(self, graph) -> dict:
        """action_msgs/msg/GoalInfo."""
        return {"goal_id": {"uuid": self.uuid}, "stamp": graph.stamp(self.stamp)}


def _duration(seconds: float) -> dict:
    """builtin_interfaces/msg/Duration."""
    return {"sec": int(seconds), "nanosec": int((seconds % 1) * 1e9)}


def _uuid_bytes(value) -> list[int]:
    """A goal uuid as a list of 16 bytes: the strict server hands uint8[16] on as base64 text, as rosbridge does."""
    if isinstance(value, str):
        return list(base64.b64decode(value))
    return list(value or [0] * 16)
