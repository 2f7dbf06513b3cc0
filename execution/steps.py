"""Running one robot's steps through its link: the session, the tick loop, goals for a nav stack, and dispatch.

Each step runs through its action's handler (execution/handlers.py, named by fleetcore/actions.py).
A Session carries what the control loop needs each tick: the next pose from odometry, the stop and preempt
flags and the lease that keeps the robot's lock (both kept by the process's board, execution.board: reading
them is no I/O), and the timing stamps (first command published, motion seen
in odometry). Every motion watches its own progress (Progress): no progress towards its goal for a while is a
stall, and a motion that takes twice its expected time plus slack is late; both end it with a reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
import uuid
from dataclasses import dataclass, field

from django.utils import timezone

from execution import blocking
from execution.board import Lease, NoAnswer
from execution.link import RobotLink
from execution.models import Execution, Instruction
from fleetcore import faults, geometry
from fleetcore import traffic_tuning as tune
from fleetcore.speed import Limits
from robots import poses as pose_store

log = logging.getLogger(__name__)

ODOMETRY_TIMEOUT = 3.0  # s without an odometry message fails the step ("no odometry for 3 s")
FAULT_GRACE_S = (
    0.5  # odometry refused on the way: halted, then this long for a good pose before the step fails
)
ODOMETRY_GAP = 0.5  # s without odometry: the robot is told to stop while we wait, and the link is looked at
STORE_POSE_EVERY = 0.5  # s between stores of the robot's own pose (the pose hub fills in between)
MOVED, TURNED = 0.02, 0.05  # m, rad: motion seen in odometry
PROGRESS_M, PROGRESS_RAD = 0.05, 0.15  # closer to the goal, or turned towards it, by this much: progress
STALL_S = 3.0  # s without progress while commanded: the robot is stalled
SLACK_S = 10.0  # s added to twice the expected time of a motion
LINK_LOST = "link lost"


class StepFailed(Exception):
    """The step cannot finish; the message says why, for a person."""


class LinkLost(StepFailed):
    """The robot's link dropped under the step: nothing we send reaches it until the link is back."""


class Aborted(StepFailed):
    """The robot's own stack gave up on a goal (move_base, nav2: after its own recoveries)."""


class Late(StepFailed):
    """The step ran out of its time with the robot still on its way (it is halted)."""


class Stalled(StepFailed):
    """The robot is commanded to move but makes no progress: something the plan did not know is in the way."""

    def __init__(self, reason: str, pose: tuple[float, float, float]) -> None:
        super().__init__(reason)
        self.pose = pose


REDIS_LOST = "executor lost: Redis unreachable, so its lock on the robot cannot be kept"
REDIS_LATE = "executor lost: Redis did not answer in time, so no stop could be seen and its lock not kept"


class Interrupted(Exception):
    """Someone stopped or preempted the robot, or its lock was lost."""

    def __init__(self, outcome: str, reason: str, preemptor: int | None = None) -> None:
        super().__init__(reason)
        self.outcome, self.reason, self.preemptor = outcome, reason, preemptor


@dataclass
class Session:
    execution: Execution
    link: RobotLink
    lease: Lease
    started: float = field(default_factory=time.time)
    seen: int = 0
    last_store: float = field(default_factory=time.monotonic)
    origin: tuple | None = None
    commanded: bool = False
    moving: bool = False
    gate_checked: bool = False  # the links process's verdict on the robot's odometry was read
    making_way: bool = False  # its trips are another's way through: planned before the rest (traffic.plan)
    stamps: list[asyncio.Future] = field(default_factory=list)  # timing stamps on their way to the database

    @property
    def robot(self):
        return self.link.robot

    def __post_init__(self) -> None:
        self.lease.watch(self.execution.pk)
        self.lease.wake = self.link.poses.nudge  # flags that change are checked at once, not at the next pose

    async def pose(self) -> tuple[float, float, float]:
        """The next odometry pose; a gap stops the robot while waiting, a dropped link or 3 s fail the step,
        and so does odometry the gate refuses (here or in the links process), at once. A flag raised meanwhile
        (a stop, a preemption, a lost lock: `check`) ends the wait when the board reads it, not at the pose."""
        await self._check_gate()
        waited = 0.0
        while True:
            self.lease.beat()
            pose, self.seen = await self.link.next_pose(self.seen, ODOMETRY_GAP, self.check)
            await self._check_gate()
            if pose is not None:
                await self._note_motion(pose)
                return pose
            waited += ODOMETRY_GAP
            if not self.link.connected:
                raise LinkLost(f"{self.robot.name}: {LINK_LOST} ({self.robot.endpoint} disconnected)")
            await self._zero()  # blind: never keep driving on a command given before odometry stopped
            if waited >= ODOMETRY_TIMEOUT:
                topic = self.link.odometry.target
                raise StepFailed(f"{self.robot.name}: no odometry on {topic} for {ODOMETRY_TIMEOUT:g} s")

    async def _check_gate(self) -> None:
        """StepFailed, the robot told to stop, when its odometry is refused: nothing can be driven on it. A robot
        flagged before the step fails at once; one whose odometry turns bad on the way is halted and given
        FAULT_GRACE_S for a good pose to come back (one hostile frame among good ones costs a pause, not the
        step; bad odometry that lasts fails it within the grace)."""
        fault = self.link.fault
        if fault is None and not self.gate_checked:
            self.gate_checked = True
            fault = self.link.flagged  # as the link was made, just before the step
            if fault is not None:
                await self._halt_on_fault(fault)
        if fault is None:
            return
        with contextlib.suppress(Exception):  # a link that is down cannot take it; the reason is the fault
            await self.link.halt()
        deadline = time.monotonic() + FAULT_GRACE_S
        while time.monotonic() < deadline:
            await asyncio.sleep(0.02)
            if self.link.fault is None:
                return
        await self._halt_on_fault(self.link.fault or fault)

    async def _halt_on_fault(self, fault: dict) -> None:
        with contextlib.suppress(Exception):  # a link that is down cannot take it; the reason is the fault
            await self.link.halt()
        raise StepFailed(pose_store.fault_words(self.robot.name, fault))

    async def _zero(self) -> None:
        try:
            await self.link.halt()
        except Exception as exc:  # the link went down between our look at it and the zero
            raise LinkLost(f"{self.robot.name}: {LINK_LOST} ({exc})") from exc

    def check(self) -> None:
        """Raise Interrupted if the robot was stopped or preempted, or its lock was lost; tell the lease. No I/O:
        the flags are the board's last read (so a plan's search may call it from its thread)."""
        lease = self.lease
        if not lease.held:
            if lease.fault:  # Redis refuses writes (a full disk): a stop cannot be seen; halted here
                raise Interrupted("failed", f"stopped; {lease.why_lost}")
            raise Interrupted("failed", f"executor lost: {lease.why_lost}")
        lease.beat()
        if lease.error is not None:  # no stop flag or preemption can be seen, no lock kept: not ours to drive
            words = faults.refusal(lease.error)  # it answers, but refuses writes: halted, and that is why
            if words:
                raise Interrupted("failed", f"stopped; {words}")
            lost = REDIS_LATE if isinstance(lease.error, NoAnswer) else REDIS_LOST
            raise Interrupted("failed", f"{lost} ({lease.error})")
        self._check_flags()

    def _check_flags(self) -> None:
        """Keep the pose now and then (the board stores it); raise Interrupted if the robot was stopped or
        preempted."""
        if time.monotonic() - self.last_store > STORE_POSE_EVERY:
            self.last_store = time.monotonic()
            if self.link.poses.value is not None:
                self.lease.keep_pose(self.link.poses.value)
        stopped_at, preemptor, cancelled = self.lease.flags
        if stopped_at > self.started:
            raise Interrupted("cancelled", "stopped")
        if cancelled is not None:
            raise Interrupted("cancelled", cancelled)
        if preemptor is not None and preemptor != self.execution.pk:
            raise Interrupted("preempted", f"preempted by instruction of execution {preemptor}", preemptor)

    async def send(self, v: float, w: float) -> None:
        """Publish a velocity command (after checking the flags, so a stop is never overridden)."""
        self.check()
        try:
            await self.link.velocity(v, w)
        except Exception as exc:  # a publish on a dropped link: the step cannot go on
            if not self.link.connected:
                raise LinkLost(f"{self.robot.name}: {LINK_LOST} ({exc})") from exc
            raise
        await self.mark_commanded()

    async def mark_commanded(self) -> None:
        if not self.commanded:
            self.commanded = True
            self._stamp_later("first_command_at")

    def _stamp_later(self, field_name: str) -> None:
        """Stamp the execution now, through the blocking pool, without waiting: the control loop never waits for
        the database while its robot moves. (With hundreds of robots' calls queued in the pool, as at 1,000
        robots on the cluster, a stamp awaited after the first command would hold the loop as long, the robot
        going on with that command.)"""
        self.stamps.append(
            asyncio.ensure_future(blocking.call(_stamp, self.execution, field_name, timezone.now()))
        )

    async def stamped(self) -> None:
        """Wait for the stamps under way (the runner, before it records the end); one that failed is logged."""
        for task in self.stamps:
            try:
                await task
            except Exception:  # the database away: the end's record says what matters
                log.warning("execution %s: a timing stamp was not kept", self.execution.pk, exc_info=True)
        self.stamps = []

    async def _note_motion(self, pose) -> None:
        if self.origin is None:
            self.origin = pose
            return
        if self.moving or not self.commanded:
            return
        moved = math.hypot(pose[0] - self.origin[0], pose[1] - self.origin[1])
        if moved > MOVED or abs(geometry.wrap(pose[2] - self.origin[2])) > TURNED:
            self.moving = True
            self._stamp_later("motion_started_at")


def _stamp(execution: Execution, field_name: str, now) -> None:
    """Set a timing field on the execution to `now` and, the first time across robots, on its instruction."""
    Execution.objects.filter(pk=execution.pk, **{f"{field_name}__isnull": True}).update(**{field_name: now})
    Instruction.objects.filter(pk=execution.instruction_id, **{f"{field_name}__isnull": True}).update(
        **{field_name: now}
    )


@dataclass
class Progress:
    """A motion's progress towards its goal: stalled after `window` s without any, late after `limit` s.

    Progress is coming PROGRESS_M closer to the goal or turning PROGRESS_RAD towards it (a robot turns on the
    spot before it drives); without a goal (a rotation, a pattern), any motion seen in odometry.
    """

    limit: float
    window: float = STALL_S
    goal: tuple[float, float] | None = None
    started: float = field(default_factory=time.monotonic)
    since: float = field(default_factory=time.monotonic)
    mark: tuple | None = None

    def update(self, pose, now: float | None = None) -> str | None:
        """Take a pose (seen at `now`, monotonic; the present by default); return None while fine, "stalled" or
        "late" (to be said by the caller)."""
        now = time.monotonic() if now is None else now
        if self.mark is None or self._progressed(self.mark, pose):
            self.mark, self.since = pose, now
        if now - self.started > self.limit:
            return "late"
        if now - self.since > self.window:
            return "stalled"
        return None

    def _progressed(self, before, after) -> bool:
        if self.goal is None:
            return _moved(before, after)
        closer = math.dist(before[:2], self.goal) - math.dist(after[:2], self.goal)
        return (
            closer > PROGRESS_M
            or _heading_error(before, self.goal) - _heading_error(after, self.goal) > PROGRESS_RAD
        )


def _heading_error(pose, goal) -> float:
    return abs(geometry.wrap(math.atan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2]))


async def at_rest(session: Session) -> tuple[float, float, float]:
    """Stop the robot and read odometry until it has come to rest (two poses within REST_M and REST_RAD, at
    most REST_LIMIT_S): where it stands. Where a step ends is judged from it, not from the pose as the robot was told
    to stop: a robot slows down within its acceleration limit (a Husky, 1 m/s², goes on 0.5 m from 1 m/s)."""
    await session.link.halt()
    deadline = time.monotonic() + tune.REST_LIMIT_S
    before = await session.pose()
    while time.monotonic() < deadline:
        now = await session.pose()
        if (
            math.dist(before[:2], now[:2]) < tune.REST_M
            and abs(geometry.wrap(now[2] - before[2])) < tune.REST_RAD
        ):
            return now
        before = now
    return before


async def drive(
    session: Session, controller, limit_s: float, stall_s: float | None = None, goal=None
) -> None:
    """Run a velocity controller tick by tick on odometry until it is done, watching its progress.

    stall_s: raise Stalled when the robot makes no progress (towards `goal`, or at all) for that long while
    commanded; Late when it has not finished within limit_s.
    """
    progress = Progress(limit_s, stall_s if stall_s is not None else math.inf, goal)
    while True:
        pose = await session.pose()
        command = controller.command(pose)
        if command.done:
            await session.link.halt()
            return
        verdict = progress.update(pose)
        if verdict == "late":
            await session.link.halt()
            raise Late(f"{session.robot.name}: did not finish within {limit_s:.0f} s")
        if verdict == "stalled":
            await session.link.halt()
            raise Stalled(
                f"{session.robot.name}: no progress for {progress.window:g} s near ({pose[0]:.1f}, {pose[1]:.1f})",
                pose,
            )
        await session.send(command.v, command.w)


def _moved(before, after) -> bool:
    return math.dist(before[:2], after[:2]) > MOVED or abs(geometry.wrap(after[2] - before[2])) > TURNED


async def navigate(
    session: Session, x: float, y: float, limit_s: float, stall_s: float | None = None
) -> None:
    """Hand the goal to the robot's navigation stack and follow its status to the end."""
    session.check()
    goal = await session.link.navigate(x, y, 0.0, f"fleet-{session.execution.pk}-{uuid.uuid4().hex[:8]}")
    await session.mark_commanded()
    await follow_goal(session, goal, limit_s, "navigation", stall_s)


NAV_WORDS = {"failed": "aborted", "cancelled": "cancelled"}  # what a stack's outcome means to a person


async def follow_goal(
    session: Session, goal, limit_s: float, what: str, stall_s: float | None = None, toward: bool = True
) -> None:
    """Follow a goal the robot's own stack runs (navigation, docking) until it ends; cancel it on any exit.

    The stack recovers by itself from most trouble (it backs off and replans); stall_s is how long we let it
    try without any progress (towards the goal's target, or without `toward` any motion) before this raises
    Stalled.
    """
    target = goal.target if toward else None
    progress = Progress(limit_s, stall_s if stall_s is not None else math.inf, target)
    try:
        while True:
            pose = await session.pose()
            session.check()
            outcome = session.link.goal_outcome(goal, pose)
            if outcome == "succeeded":
                return
            if outcome == "failed":
                raise Aborted(f"{session.robot.name}: {what} {NAV_WORDS[outcome]}")
            if outcome in NAV_WORDS:
                await _stop_behind_cancel(session)
                raise StepFailed(f"{session.robot.name}: {what} {NAV_WORDS[outcome]}")
            verdict = progress.update(pose)
            if verdict == "late":
                raise StepFailed(f"{session.robot.name}: {what} did not finish within {limit_s:.0f} s")
            if verdict == "stalled":
                raise Stalled(
                    f"{session.robot.name}: {what} made no progress for {progress.window:g} s", pose
                )
    except BaseException:
        with contextlib.suppress(Exception):  # a link that is down cannot take it; the first reason is kept
            await session.link.halt(goal)
        raise


CANCEL_GRACE_S = 0.5  # a stop sends its zeros and cancels first and raises its flags after (fast_stop)


async def _stop_behind_cancel(session: Session) -> None:
    """A stack's goal cancelled from outside is, most often, a person's stop whose flags are not up yet: look for
    them a moment (Interrupted: the step ends "stopped", not failed) before calling it the stack's doing."""
    deadline = time.monotonic() + CANCEL_GRACE_S
    while time.monotonic() < deadline:
        session.check()
        await asyncio.sleep(0.05)


def travel_time(distance: float, turn: float, limits: Limits) -> float:
    """The limit of a motion driven within these limits (a step's pace: fleetcore.speed): twice the time it
    takes at them, plus slack (accelerations, corners, a slow link)."""
    return 2 * (distance / limits.linear + turn / limits.angular) + SLACK_S


def advance(execution: Execution, index: int) -> None:
    Execution.objects.filter(pk=execution.pk).update(step_index=index)
