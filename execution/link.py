"""A robot's command link: its bound topics, spoken in its message types, over the shared rosbridge client.

Publishing goes through robots.rosbridge.sync (one link per endpoint per process). Poses come from the
odometry binding composed with the robot's start pose, corrected by amcl_pose when the robot has one.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time
from dataclasses import dataclass

from fleetcore import geometry, motion
from robots.models import Binding, Robot

NAV_MOVE_BASE, NAV_NAV2, NAV_SIMPLE = "move_base", "nav2", "simple"


class LinkError(RuntimeError):
    """The robot cannot be commanded: no binding for the action, or the endpoint is down."""


def bindings_of(robot: Robot) -> dict[str, Binding]:
    return {b.action: b for b in robot.bindings.all() if b.target}


def navigation_kind(binding: Binding | None) -> str | None:
    """How the robot's navigate binding takes goals: move_base action, nav2 action, or a PoseStamped topic."""
    if binding is None:
        return None
    kind = binding.message_type or ""
    if "NavigateToPose" in kind:
        return NAV_NAV2
    if "MoveBase" in kind or binding.target.rstrip("/").endswith("move_base"):
        return NAV_MOVE_BASE
    if kind.endswith("PoseStamped"):
        return NAV_SIMPLE
    return None


def action_namespace(target: str) -> str:
    """The action's name from a bound target such as /move_base/goal or /navigate_to_pose/_action/send_goal."""
    for suffix in (
        "/_action/send_goal",
        "/_action/feedback",
        "/_action/status",
        "/goal",
        "/status",
        "/result",
    ):
        if target.endswith(suffix):
            return target[: -len(suffix)]
    return target.rstrip("/")


def client_for(robot: Robot):
    from robots.rosbridge.sync import get_client

    try:
        return get_client(robot.endpoint)
    except Exception as exc:  # unreachable endpoint, timeout: a one-line reason for the outcome
        raise LinkError(f"{robot.name}: cannot reach {robot.endpoint}: {exc}") from exc


def publish_zero(robot: Robot, bindings: dict[str, Binding] | None = None) -> None:
    """Publish a zero velocity on the robot's move topic and cancel its ROS 1 navigation goal, now."""
    bindings = bindings if bindings is not None else bindings_of(robot)
    move = bindings.get("move")
    if move is None:
        raise LinkError(f"{robot.name}: no move topic is bound")
    client = client_for(robot)
    message = motion.velocity_message(0.0, 0.0, move.message_type, robot.ros_version, time.time())
    client.publish(move.target, message, move.message_type or "geometry_msgs/Twist")
    navigate = bindings.get("navigate")
    if navigation_kind(navigate) == NAV_MOVE_BASE:
        cancel = f"{action_namespace(navigate.target)}/cancel"
        client.publish(cancel, motion.goal_id("", time.time()), "actionlib_msgs/GoalID")


class Latest:
    """The latest value a subscription delivered, with a counter to wait for the next one."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.value = None
        self.count = 0

    def put(self, value) -> None:
        with self.cond:
            self.value, self.count = value, self.count + 1
            self.cond.notify_all()

    def next(self, seen: int, timeout: float):
        """(value, count) once count > seen, or (None, seen) on timeout."""
        with self.cond:
            if not self.cond.wait_for(lambda: self.count > seen, timeout):
                return None, seen
            return self.value, self.count


@dataclass
class Goal:
    """A navigation goal in flight."""

    kind: str
    id: str
    target: tuple[float, float]
    handle: object = None  # the ROS 2 ActionGoal
    result: object = None  # a concurrent future of its result


class RobotLink:
    """Command one robot and watch its pose: open() before use, close() after."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.bindings = bindings_of(robot)
        self.move = self.bindings.get("move")
        if self.move is None:
            raise LinkError(f"{robot.name}: no move topic is bound; choose one on its registration page")
        self.odometry = self.bindings.get("odometry")
        if self.odometry is None:
            raise LinkError(f"{robot.name}: no odometry topic is bound; choose one on its registration page")
        self.nav_kind = navigation_kind(self.bindings.get("navigate"))
        self.start = tuple(robot.start_pose) if robot.start_pose else (0.0, 0.0, 0.0)
        self.local = None  # the last odometry pose, in the odometry frame
        self.poses = Latest()
        self.nav_status = Latest()
        self.client = None
        self._subs = []

    # ----- lifecycle -----
    def open(self) -> RobotLink:
        self.client = client_for(self.robot)
        self._subscribe(
            self.odometry.target, self.odometry.message_type or "nav_msgs/Odometry", self._on_odom
        )
        pose = self.bindings.get("pose")
        if pose is not None:
            self._subscribe(pose.target, pose.message_type or "", self._on_amcl)
        if self.nav_kind == NAV_MOVE_BASE:
            ns = action_namespace(self.bindings["navigate"].target)
            self._subscribe(f"{ns}/status", "actionlib_msgs/GoalStatusArray", self.nav_status.put)
        return self

    def _subscribe(self, topic: str, type_: str, callback) -> None:
        self._subs.append(self.client.subscribe(topic, type_, callback))

    @property
    def connected(self) -> bool:
        """Whether the rosbridge link is up now (it reconnects by itself; subscriptions come back with it)."""
        return self.client is not None and self.client.client.is_connected

    def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(Exception):  # the link may be down; nothing else to release
                self.client.unsubscribe(sub)
        self._subs = []

    # ----- poses -----
    def _on_odom(self, msg: dict) -> None:
        self.local = geometry.pose_of(msg)
        self.poses.put(geometry.compose(self.start, self.local))

    def _on_amcl(self, msg: dict) -> None:
        """Move the odometry origin so that the current odometry pose lands on the amcl estimate."""
        if self.local is None:
            return
        ax, ay, ayaw = geometry.pose_of(msg)
        lx, ly, lyaw = self.local
        yaw0 = geometry.wrap(ayaw - lyaw)
        c, s = math.cos(yaw0), math.sin(yaw0)
        self.start = (ax - (c * lx - s * ly), ay - (s * lx + c * ly), yaw0)

    def next_pose(self, seen: int, timeout: float = 1.0):
        """((x, y, yaw) on the map, counter) after the next odometry message; (None, seen) on timeout."""
        return self.poses.next(seen, timeout)

    # ----- commands -----
    def velocity(self, v: float, w: float) -> None:
        message = motion.velocity_message(v, w, self.move.message_type, self.robot.ros_version, time.time())
        self.client.publish(self.move.target, message, self.move.message_type or "geometry_msgs/Twist")

    def halt(self, goal: Goal | None = None) -> None:
        """Zero velocity, and cancel the navigation goal if one is in flight."""
        if goal is not None:
            self.cancel(goal)
        self.velocity(0.0, 0.0)

    def navigate(self, x: float, y: float, yaw: float, goal_id: str) -> Goal:
        """Send a navigation goal the way this robot's stack takes it."""
        target = self.bindings["navigate"]
        now = time.time()
        if self.nav_kind == NAV_MOVE_BASE:
            ns = action_namespace(target.target)
            message = motion.move_base_goal(x, y, yaw, goal_id, now)
            self.client.publish(f"{ns}/goal", message, "move_base_msgs/MoveBaseActionGoal")
            return Goal(NAV_MOVE_BASE, goal_id, (x, y))
        if self.nav_kind == NAV_NAV2:
            ns = action_namespace(target.target)
            handle = self.client.send_action_goal(
                ns, "nav2_msgs/action/NavigateToPose", motion.navigate_to_pose_goal(x, y, yaw, now)
            )
            result = asyncio.run_coroutine_threadsafe(handle.wait(None), self.client.runner.loop)
            return Goal(NAV_NAV2, handle.id, (x, y), handle, result)
        message = motion.pose_stamped(x, y, yaw, now, self.robot.ros_version)
        self.client.publish(target.target, message, target.message_type)
        return Goal(NAV_SIMPLE, goal_id, (x, y))

    def goal_outcome(self, goal: Goal, pose) -> str | None:
        """succeeded / failed / cancelled once the stack says so, else None (still active)."""
        if goal.kind == NAV_MOVE_BASE:
            status = self.nav_status.value
            return motion.move_base_outcome(status, goal.id) if status else None
        if goal.kind == NAV_NAV2:
            if not goal.result.done():
                return None
            try:
                reply = goal.result.result()
            except Exception:
                return "failed"
            return motion.ROS2_GOAL_STATUS.get(int(reply.get("status", 0)), "failed")
        near = pose is not None and ((pose[0] - goal.target[0]) ** 2 + (pose[1] - goal.target[1]) ** 2) ** 0.5
        return "succeeded" if near is not False and near < 0.25 else None

    @property
    def can_dock(self) -> bool:
        """Whether the robot has a docking action server bound (a ROS 2 action such as the Create 3's dock)."""
        return "dock" in self.bindings and self.robot.ros_version == 2

    def dock(self) -> Goal:
        """Start the robot's own docking action; follow it with goal_outcome, stop it with cancel."""
        binding = self.bindings["dock"]
        ns = action_namespace(binding.target)
        action_type = binding.message_type or "irobot_create_msgs/action/Dock"
        handle = self.client.send_action_goal(ns, action_type, {})
        result = asyncio.run_coroutine_threadsafe(handle.wait(None), self.client.runner.loop)
        return Goal(NAV_NAV2, handle.id, tuple(self.robot.start_pose or (0.0, 0.0))[:2], handle, result)

    def cancel(self, goal: Goal) -> None:
        if goal.kind == NAV_MOVE_BASE:
            ns = action_namespace(self.bindings["navigate"].target)
            self.client.publish(f"{ns}/cancel", motion.goal_id(goal.id, time.time()), "actionlib_msgs/GoalID")
        elif goal.kind == NAV_NAV2:
            self.client.cancel_action_goal(goal.handle)

    def limits(self) -> motion.Limits:
        return motion.Limits(self.robot.max_linear, self.robot.max_angular)
