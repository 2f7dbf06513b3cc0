"""A robot's command link: its bound topics, spoken in its message types, over the shared rosbridge client.

Publishing goes through robots.rosbridge.sync (one link per endpoint per process). Poses come from the
odometry binding composed with the robot's start pose, corrected by amcl_pose when the robot has one; the
odometry passes the robot's gate first (fleetcore.posegate), and a refused message wakes whoever waits for a
pose, so the step fails at once with the reason (`fault`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import threading
import time
from dataclasses import dataclass

from fleetcore import geometry, motion
from fleetcore.posegate import InvalidOdometry, PoseGate
from fleetcore.speed import Limits
from robots import commands
from robots import poses as pose_store
from robots.commands import NAV_MOVE_BASE, NAV_NAV2, NAV_SIMPLE, CommandSurface
from robots.models import Robot
from robots.rosbridge import sync

PHOTO_TICK_S = 0.25  # waiting for a camera frame, the session is checked this often (stops, its heartbeat)


class LinkError(RuntimeError):
    """The robot cannot be commanded: no binding for the action, or the endpoint is down."""


def client_for(robot: Robot):
    try:
        return sync.get_client(robot.endpoint)
    except Exception as exc:  # unreachable endpoint, timeout: a one-line reason for the outcome
        raise LinkError(f"{robot.name}: cannot reach {robot.endpoint}: {exc}") from exc


def publish_all(client, items, wait: bool = False) -> list:
    """Send a surface's commands (publishes, service calls) on a sync client; the calls' answers with `wait`."""
    return client.runner.run(commands.send(client.client, items, wait), commands.CALL_TIMEOUT + 1.0)


def publish_zero(robot: Robot) -> None:
    """Publish a zero velocity on the robot's move topic and cancel its navigation goal, now (a goal topic's
    robot: a goal where its last pose says it is)."""
    surface = CommandSurface.of(robot)
    if not surface.can_move:
        raise LinkError(f"{robot.name}: no move topic is bound")
    here = None
    if surface.nav_kind == NAV_SIMPLE:
        pose = pose_store.last_poses([robot.pk]).get(robot.pk)
        here = (pose["x"], pose["y"], pose["yaw"]) if pose else None
    publish_all(client_for(robot), surface.zero(here=here))


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
        bound = {b.action: b for b in robot.bindings.all() if b.target}
        self.surface = CommandSurface.of(robot, bound.values())
        if not self.surface.can_move:
            raise LinkError(f"{robot.name}: no move topic is bound; choose one on its registration page")
        self.odometry = bound.get("odometry")
        if self.odometry is None:
            raise LinkError(f"{robot.name}: no odometry topic is bound; choose one on its registration page")
        self.amcl = bound.get("pose")
        self.camera = bound.get("camera")
        self.nav_kind = self.surface.nav_kind
        self.start = tuple(robot.start_pose) if robot.start_pose else (0.0, 0.0, 0.0)
        self.local = None  # the last odometry pose, in the odometry frame
        self.poses = Latest()
        self.gate = PoseGate(robot.max_linear)
        self.clock = motion.ClockRate()  # its clock against ours (a simulator may run faster than real time)
        self.nav_status = Latest()
        self.client = None
        self._subs = []

    # ----- lifecycle -----
    def open(self) -> RobotLink:
        self.client = client_for(self.robot)
        self._subscribe(
            self.odometry.target, self.odometry.message_type or "nav_msgs/Odometry", self._on_odom
        )
        if self.amcl is not None:
            self._subscribe(self.amcl.target, self.amcl.message_type or "", self._on_amcl)
        if self.nav_kind == NAV_MOVE_BASE:
            ns = self.surface.nav_namespace
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
        try:
            reading = self.gate.admit(msg, time.time())
        except InvalidOdometry:
            self.poses.put(self.poses.value)  # wake the step waiting for a pose: it fails with the reason
            return
        self.local = reading.pose
        self.poses.put(geometry.compose(self.start, self.local))
        self.clock.update(time.monotonic(), reading.stamp)

    @property
    def fault(self) -> dict | None:
        """Why the gate refuses this robot's odometry now, as a pose record says it ("fault", "fault_since")."""
        if self.gate.fault is None:
            return None
        return {"fault": self.gate.fault, "fault_since": self.gate.since}

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

    # ----- camera -----
    def photo(self, timeout: float, between=None) -> dict:
        """The next frame on the robot's camera binding (the message as rosbridge gives it), from a subscription
        of its own held only till then; `between()` is called every PHOTO_TICK_S meanwhile (the session's check:
        a stop ends the wait). LinkError when no camera is bound or no frame comes within `timeout` s."""
        camera = self.camera
        if camera is None:
            raise LinkError(f"{self.robot.name}: no camera topic is bound")
        frame = Latest()
        sub = self.client.subscribe(camera.target, camera.message_type, frame.put, queue_length=1)
        try:
            until = time.monotonic() + timeout
            while (left := until - time.monotonic()) > 0:
                message, _ = frame.next(0, min(PHOTO_TICK_S, left))
                if message is not None:
                    return message
                if between is not None:
                    between()
        finally:
            with contextlib.suppress(Exception):  # the link may be down; nothing else to release
                self.client.unsubscribe(sub)
        raise LinkError(f"{self.robot.name}: no frame from {camera.target} within {timeout:g} s")

    # ----- commands -----
    def velocity(self, v: float, w: float) -> None:
        self.client.publish(*self.surface.velocity(v, w))

    def halt(self, goal: Goal | None = None) -> None:
        """Zero velocity, and cancel the navigation goal if one is in flight."""
        if goal is not None:
            self.cancel(goal)
        self.velocity(0.0, 0.0)

    def navigate(self, x: float, y: float, yaw: float, goal_id: str) -> Goal:
        """Send a navigation goal the way this robot's stack takes it."""
        now = time.time()
        if self.nav_kind == NAV_MOVE_BASE:
            self.client.publish(*self.surface.move_base_goal(x, y, yaw, goal_id, now))
            return Goal(NAV_MOVE_BASE, goal_id, (x, y))
        if self.nav_kind == NAV_NAV2:
            handle = self.client.send_action_goal(
                self.surface.nav_namespace,
                "nav2_msgs/action/NavigateToPose",
                motion.navigate_to_pose_goal(x, y, yaw, now),
            )
            result = asyncio.run_coroutine_threadsafe(handle.wait(None), self.client.runner.loop)
            return Goal(NAV_NAV2, handle.id, (x, y), handle, result)
        self.client.publish(*self.surface.simple_goal(x, y, yaw, now))
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
        return self.surface.can_dock

    def dock(self) -> Goal:
        """Start the robot's own docking action; follow it with goal_outcome, stop it with cancel."""
        surface = self.surface
        handle = self.client.send_action_goal(surface.dock_namespace, surface.dock_type, {})
        result = asyncio.run_coroutine_threadsafe(handle.wait(None), self.client.runner.loop)
        return Goal(NAV_NAV2, handle.id, tuple(self.robot.start_pose or (0.0, 0.0))[:2], handle, result)

    def cancel(self, goal: Goal) -> None:
        """Cancel the goal as its stack takes it; a goal topic has no cancel: a goal where the robot is."""
        if goal.kind == NAV_MOVE_BASE:
            self.client.publish(*self.surface.cancel_move_base(goal.id))
        elif goal.kind == NAV_NAV2:
            self.client.cancel_action_goal(goal.handle)
        elif goal.kind == NAV_SIMPLE and self.poses.value is not None:
            self.client.publish(*self.surface.simple_goal(*self.poses.value, time.time()))

    # ----- speed -----
    @contextlib.contextmanager
    def speed_limited(self, share: float | None):
        """Hold the navigation stack at `share` of its own top speed for the block (None: its own top speed),
        and give it its own top speed back after, however the block ends. LinkError when the stack does not
        take the limit (before anything moves)."""
        surface = self.surface
        try:
            top = self._planner_top() if surface.speed_kind == "service" else None
            publish_all(self.client, [surface.speed_limit(share, top)], wait=True)
        except Exception as exc:  # the service refused or did not answer: the word cannot be kept
            raise LinkError(f"{self.robot.name}: its navigation stack took no speed limit ({exc})") from exc
        try:
            yield
        finally:
            with contextlib.suppress(
                Exception
            ):  # a link that is down cannot take it; the next trip sets it again
                publish_all(self.client, [surface.speed_limit(None, top)], wait=True)

    def _planner_top(self) -> float:
        """The local planner's max_vel_x as registered (its configured top speed), else as it reads now."""
        planner = self.surface.speed_target.removesuffix("/set_parameters")
        text = self.robot.params.filter(name=f"{planner}/max_vel_x").values_list("value", flat=True).first()
        with contextlib.suppress(TypeError, ValueError):
            value = float(json.loads(text))
            if math.isfinite(value) and value > 0:
                return value
        (reply,) = publish_all(self.client, [self.surface.read_speed()], wait=True)
        top = motion.reconfigured(reply, "max_vel_x")
        if top is None:
            raise LinkError(f"{self.robot.name}: {planner} has no max_vel_x")
        return top

    def limits(self) -> Limits:
        return Limits(self.robot.max_linear, self.robot.max_angular)
