"""A robot's command link: its bound topics, spoken in its message types, over the shared rosbridge client.

RobotLink lives on the executor's event loop, next to the robot's task: it publishes on that loop's own
rosbridge client (robots.rosbridge.pool, one per endpoint per loop) and its subscriptions' callbacks run there.
publish_zero, for the synchronous callers that stop a robot (control, the watchdog), goes through
robots.rosbridge.sync. Poses come from the
odometry binding composed with the robot's start pose, corrected by amcl_pose when the robot has one; the
odometry passes the robot's gate first (fleetcore.posegate), and a refused message wakes whoever waits for a
pose, so the step fails at once with the reason (`fault`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from dataclasses import dataclass

from fleetcore import geometry, motion
from fleetcore.posegate import InvalidOdometry, PoseGate
from fleetcore.speed import Limits
from robots import commands
from robots import poses as pose_store
from robots.commands import NAV_MOVE_BASE, NAV_NAV2, NAV_SIMPLE, CommandSurface
from robots.models import Robot
from robots.rosbridge import pool, sync
from robots.rosbridge.client import throttle_for

PHOTO_TICK_S = 0.25  # waiting for a camera frame, the session is checked this often (stops, its heartbeat)
# A driven robot's odometry is followed at most at this period (robots.rosbridge.client.throttle_for: the newest
# message past the throttle, none held), and each message is a control tick: 10 Hz, half a TurtleBot's own 20 Hz,
# for half the frames its executor and its robot's rosbridge handle (docs/scale.md). A stop does not wait for a tick: its flag wakes the
# session between poses (execution.board, Lease.wake), so it is acted on one Redis round trip after its flag
# (tests/execution/test_board.py, test_queueing.py); a turn or a drive comes to rest as near its goal as at 20 Hz
# (tests/execution/test_motion.py: commands 0.1 s apart).
CONTROL_MS = 100


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


def publish_zero(robot: Robot, surface: CommandSurface | None = None) -> None:
    """Publish a zero velocity on the robot's move topic and cancel its navigation goal, now (a goal topic's
    robot: a goal where its last pose says it is); surface: the robot's, if the caller has it (else read)."""
    surface = surface or CommandSurface.of(robot)
    if not surface.can_move:
        raise LinkError(f"{robot.name}: no move topic is bound")
    here = None
    if surface.nav_kind == NAV_SIMPLE:
        pose = pose_store.last_poses([robot.pk]).get(robot.pk)
        here = (pose["x"], pose["y"], pose["yaw"]) if pose else None
    publish_all(client_for(robot), surface.zero(here=here))


class Latest:
    """The latest value a subscription delivered, with a counter to wait for the next one (on the link's loop)."""

    def __init__(self) -> None:
        self.value = None
        self.count = 0
        self._changed = asyncio.Event()

    def put(self, value) -> None:
        self.value, self.count = value, self.count + 1
        self.nudge()

    def nudge(self) -> None:
        """Wake whoever waits in `next`, with no new value: its `between` is called."""
        self._changed.set()
        self._changed = asyncio.Event()

    async def next(self, seen: int, timeout: float, between=None):
        """(value, count) once count > seen, or (None, seen) on timeout; `between()` is called on each nudge
        meanwhile (it may raise, ending the wait)."""
        deadline = time.monotonic() + timeout
        while self.count <= seen:
            left = deadline - time.monotonic()
            if left <= 0:
                return None, seen
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(left):  # no task per wait, as wait_for makes (each control tick)
                    await self._changed.wait()
            if between is not None and self.count <= seen:
                between()
        return self.value, self.count


@dataclass
class Goal:
    """A navigation goal in flight."""

    kind: str
    id: str
    target: tuple[float, float]
    handle: object = None  # the ROS 2 ActionGoal
    result: asyncio.Future | None = None  # its result, awaited on the link's loop


class RobotLink:
    """Command one robot and watch its pose, on the executor's event loop: build it off the loop (its bindings
    are read from the database), then `await open()` before use and `await close()` after."""

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
        self._planner_max = self._registered_planner_top()
        # the links process's verdict on its odometry as the link is made (robots.poses), read here off the loop
        # with the bindings: a robot flagged before its step fails at once (execution.steps.Session)
        self.flagged: dict | None = pose_store.pose_faults([robot.pk]).get(robot.pk)

    # ----- lifecycle -----
    async def open(self) -> RobotLink:
        try:
            self.client = await pool.client(self.robot.endpoint)
        except Exception as exc:  # unreachable endpoint, timeout: a one-line reason for the outcome
            raise LinkError(f"{self.robot.name}: cannot reach {self.robot.endpoint}: {exc}") from exc
        odometry = self.odometry
        await self._subscribe(
            odometry.target,
            odometry.message_type or "nav_msgs/Odometry",
            self._on_odom,
            throttle_for(CONTROL_MS),
        )
        if self.amcl is not None:
            await self._subscribe(self.amcl.target, self.amcl.message_type or "", self._on_amcl)
        if self.nav_kind == NAV_MOVE_BASE:
            ns = self.surface.nav_namespace
            await self._subscribe(f"{ns}/status", "actionlib_msgs/GoalStatusArray", self.nav_status.put)
        return self

    async def _subscribe(self, topic: str, type_: str, callback, throttle_rate: int = 0) -> None:
        self._subs.append(await self.client.subscribe(topic, type_, callback, throttle_rate))

    @property
    def connected(self) -> bool:
        """Whether the rosbridge link is up now (it reconnects by itself; subscriptions come back with it)."""
        return self.client is not None and self.client.is_connected

    async def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(Exception):  # the link may be down; nothing else to release
                await self.client.unsubscribe(sub)
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

    async def next_pose(self, seen: int, timeout: float = 1.0, between=None):
        """((x, y, yaw) on the map, counter) after the next odometry message; (None, seen) on timeout;
        `between()` is called whenever the wait is nudged (`poses.nudge`) before then."""
        return await self.poses.next(seen, timeout, between)

    # ----- camera -----
    async def photo(self, timeout: float, between=None) -> dict:
        """The next frame on the robot's camera binding (the message as rosbridge gives it), from a subscription
        of its own held only till then; `between()` is called every PHOTO_TICK_S meanwhile (the session's check:
        a stop ends the wait). LinkError when no camera is bound or no frame comes within `timeout` s."""
        camera = self.camera
        if camera is None:
            raise LinkError(f"{self.robot.name}: no camera topic is bound")
        frame = Latest()
        sub = await self.client.subscribe(camera.target, camera.message_type, frame.put, queue_length=1)
        try:
            until = time.monotonic() + timeout
            while (left := until - time.monotonic()) > 0:
                message, _ = await frame.next(0, min(PHOTO_TICK_S, left))
                if message is not None:
                    return message
                if between is not None:
                    between()
        finally:
            with contextlib.suppress(Exception):  # the link may be down; nothing else to release
                await self.client.unsubscribe(sub)
        raise LinkError(f"{self.robot.name}: no frame from {camera.target} within {timeout:g} s")

    # ----- commands -----
    async def velocity(self, v: float, w: float) -> None:
        await self.client.publish(*self.surface.velocity(v, w))

    async def halt(self, goal: Goal | None = None) -> None:
        """Zero velocity, and cancel the navigation goal if one is in flight."""
        if goal is not None:
            await self.cancel(goal)
        await self.velocity(0.0, 0.0)

    async def navigate(self, x: float, y: float, yaw: float, goal_id: str) -> Goal:
        """Send a navigation goal the way this robot's stack takes it."""
        now = time.time()
        if self.nav_kind == NAV_MOVE_BASE:
            await self.client.publish(*self.surface.move_base_goal(x, y, yaw, goal_id, now))
            return Goal(NAV_MOVE_BASE, goal_id, (x, y))
        if self.nav_kind == NAV_NAV2:
            handle = await self.client.send_action_goal(
                self.surface.nav_namespace,
                "nav2_msgs/action/NavigateToPose",
                motion.navigate_to_pose_goal(x, y, yaw, now),
            )
            return Goal(NAV_NAV2, handle.id, (x, y), handle, asyncio.ensure_future(handle.wait(None)))
        await self.client.publish(*self.surface.simple_goal(x, y, yaw, now))
        return Goal(NAV_SIMPLE, goal_id, (x, y))

    def goal_outcome(self, goal: Goal, pose) -> str | None:
        """succeeded / failed / cancelled once the stack says so, else None (still active)."""
        if goal.kind == NAV_MOVE_BASE:
            status = self.nav_status.value
            return motion.move_base_outcome(status, goal.id) if status else None
        if goal.kind == NAV_NAV2:
            if not goal.result.done():
                return None
            if goal.result.cancelled() or goal.result.exception() is not None:
                return "failed"
            return motion.ROS2_GOAL_STATUS.get(int(goal.result.result().get("status", 0)), "failed")
        near = pose is not None and ((pose[0] - goal.target[0]) ** 2 + (pose[1] - goal.target[1]) ** 2) ** 0.5
        return "succeeded" if near is not False and near < 0.25 else None

    @property
    def can_dock(self) -> bool:
        """Whether the robot has a docking action server bound (a ROS 2 action such as the Create 3's dock)."""
        return self.surface.can_dock

    async def dock(self) -> Goal:
        """Start the robot's own docking action; follow it with goal_outcome, stop it with cancel."""
        surface = self.surface
        handle = await self.client.send_action_goal(surface.dock_namespace, surface.dock_type, {})
        home = tuple(self.robot.start_pose or (0.0, 0.0))[:2]
        return Goal(NAV_NAV2, handle.id, home, handle, asyncio.ensure_future(handle.wait(None)))

    async def cancel(self, goal: Goal) -> None:
        """Cancel the goal as its stack takes it; a goal topic has no cancel: a goal where the robot is."""
        if goal.kind == NAV_MOVE_BASE:
            await self.client.publish(*self.surface.cancel_move_base(goal.id))
        elif goal.kind == NAV_NAV2:
            await self.client.cancel_action_goal(goal.handle)
        elif goal.kind == NAV_SIMPLE and self.poses.value is not None:
            await self.client.publish(*self.surface.simple_goal(*self.poses.value, time.time()))

    # ----- speed -----
    @contextlib.asynccontextmanager
    async def speed_limited(self, share: float | None):
        """Hold the navigation stack at `share` of its own top speed for the block (None: its own top speed),
        and give it its own top speed back after, however the block ends. LinkError when the stack does not
        take the limit (before anything moves)."""
        surface = self.surface
        try:
            top = await self._planner_top() if surface.speed_kind == "service" else None
            await self._call([surface.speed_limit(share, top)])
        except Exception as exc:  # the service refused or did not answer: the word cannot be kept
            raise LinkError(f"{self.robot.name}: its navigation stack took no speed limit ({exc})") from exc
        try:
            yield
        finally:
            with contextlib.suppress(
                Exception
            ):  # a link that is down cannot take it; the next trip sets it again
                await self._call([surface.speed_limit(None, top)])

    async def _call(self, items) -> list:
        return await asyncio.wait_for(commands.send(self.client, items, True), commands.CALL_TIMEOUT + 1.0)

    def _registered_planner_top(self) -> float | None:
        """The local planner's max_vel_x as registered (its configured top speed), if any (read with the
        bindings, off the loop)."""
        if self.surface.speed_kind != "service":
            return None
        planner = self.surface.speed_target.removesuffix("/set_parameters")
        text = self.robot.params.filter(name=f"{planner}/max_vel_x").values_list("value", flat=True).first()
        with contextlib.suppress(TypeError, ValueError):
            value = float(json.loads(text))
            if math.isfinite(value) and value > 0:
                return value
        return None

    async def _planner_top(self) -> float:
        """The local planner's top speed as registered, else as it reads now."""
        if self._planner_max is not None:
            return self._planner_max
        (reply,) = await self._call([self.surface.read_speed()])
        top = motion.reconfigured(reply, "max_vel_x")
        if top is None:
            planner = self.surface.speed_target.removesuffix("/set_parameters")
            raise LinkError(f"{self.robot.name}: {planner} has no max_vel_x")
        return top

    def limits(self) -> Limits:
        return Limits(self.robot.max_linear, self.robot.max_angular)
