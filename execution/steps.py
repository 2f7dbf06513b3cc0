"""Running one robot's steps through its link: the session, the tick loop, goals for a nav stack, and dispatch.

Each step runs through its action's handler (execution/handlers.py, named by fleetcore/actions.py).
A Session carries what the control loop needs each tick: the next pose from odometry, the stop and preempt
flags, the lock renewal, and the timing stamps (first command published, motion seen in odometry).
"""

from __future__ import annotations

import math
import time
import uuid
from dataclasses import dataclass, field

from django.utils import timezone
from django.utils.module_loading import import_string

from execution import coordination
from execution.link import RobotLink
from execution.models import Execution, Instruction
from fleetcore import geometry, motion
from fleetcore.steps import Step
from robots import poses as pose_store

ODOMETRY_TIMEOUT = 1.0  # s without an odometry message fails the step
RENEW_EVERY = 0.5  # s between lock renewals (the lock lives LOCK_TTL_MS)
MOVED, TURNED = 0.02, 0.05  # m, rad: motion seen in odometry


class StepFailed(Exception):
    """The step cannot finish; the message says why, for a person."""


class Interrupted(Exception):
    """Someone stopped or preempted the robot, or its lock was lost."""

    def __init__(self, outcome: str, reason: str, preemptor: int | None = None) -> None:
        super().__init__(reason)
        self.outcome, self.reason, self.preemptor = outcome, reason, preemptor


@dataclass
class Session:
    execution: Execution
    link: RobotLink
    lock: coordination.RobotLock
    started: float = field(default_factory=time.time)
    seen: int = 0
    last_renew: float = field(default_factory=time.monotonic)
    origin: tuple | None = None
    commanded: bool = False
    moving: bool = False

    @property
    def robot(self):
        return self.link.robot

    def pose(self) -> tuple[float, float, float]:
        pose, self.seen = self.link.next_pose(self.seen, ODOMETRY_TIMEOUT)
        if pose is None:
            topic = self.link.odometry.target
            raise StepFailed(f"{self.robot.name}: no odometry on {topic} for {ODOMETRY_TIMEOUT:g} s")
        self._note_motion(pose)
        return pose

    def check(self) -> None:
        """Raise Interrupted if the robot was stopped or preempted, or the lock was lost; renew it."""
        if time.monotonic() - self.last_renew > RENEW_EVERY:
            if not self.lock.renew():
                raise Interrupted("failed", "lost the robot lock (another worker took over)")
            self.last_renew = time.monotonic()
            if self.link.poses.value is not None:
                pose_store.store_pose(self.robot.pk, self.link.poses.value)
        stopped_at, preemptor = coordination.flags(self.robot.pk)
        if stopped_at > self.started:
            raise Interrupted("cancelled", "stopped")
        if preemptor is not None and preemptor != self.execution.pk:
            raise Interrupted("preempted", f"preempted by instruction of execution {preemptor}", preemptor)

    def send(self, v: float, w: float) -> None:
        """Publish a velocity command (after checking the flags, so a stop is never overridden)."""
        self.check()
        self.link.velocity(v, w)
        self.mark_commanded()

    def mark_commanded(self) -> None:
        if not self.commanded:
            self.commanded = True
            _stamp(self.execution, "first_command_at")

    def _note_motion(self, pose) -> None:
        if self.origin is None:
            self.origin = pose
            return
        if self.moving or not self.commanded:
            return
        moved = math.hypot(pose[0] - self.origin[0], pose[1] - self.origin[1])
        if moved > MOVED or abs(geometry.wrap(pose[2] - self.origin[2])) > TURNED:
            self.moving = True
            _stamp(self.execution, "motion_started_at")


def _stamp(execution: Execution, field_name: str) -> None:
    """Set a timing field on the execution and, the first time across robots, on its instruction."""
    now = timezone.now()
    Execution.objects.filter(pk=execution.pk, **{f"{field_name}__isnull": True}).update(**{field_name: now})
    Instruction.objects.filter(pk=execution.instruction_id, **{f"{field_name}__isnull": True}).update(
        **{field_name: now}
    )


class Blocked(StepFailed):
    """The robot is commanded to move but does not: something the plan did not know stands in the way."""


def drive(session: Session, controller, limit_s: float, blocked_s: float | None = None) -> None:
    """Run a velocity controller tick by tick on odometry until it is done.

    blocked_s: raise Blocked when the robot has not moved (2 cm, 3 degrees) for that long while commanded.
    """
    deadline = time.monotonic() + limit_s
    still_since, still_pose = time.monotonic(), None
    while True:
        pose = session.pose()
        command = controller.command(pose)
        if command.done:
            session.link.halt()
            return
        now = time.monotonic()
        if now > deadline:
            session.link.halt()
            raise StepFailed(f"{session.robot.name}: did not finish within {limit_s:.0f} s")
        if still_pose is None or _moved(still_pose, pose):
            still_since, still_pose = now, pose
        elif blocked_s is not None and now - still_since > blocked_s:
            session.link.halt()
            raise Blocked(f"{session.robot.name}: blocked near ({pose[0]:.1f}, {pose[1]:.1f})")
        session.send(command.v, command.w)


def _moved(before, after) -> bool:
    return math.dist(before[:2], after[:2]) > 0.02 or abs(geometry.wrap(after[2] - before[2])) > 0.05


def navigate(session: Session, x: float, y: float, limit_s: float) -> None:
    """Hand the goal to the robot's navigation stack and follow its status to the end."""
    session.check()
    goal = session.link.navigate(x, y, 0.0, f"fleet-{session.execution.pk}-{uuid.uuid4().hex[:8]}")
    session.mark_commanded()
    follow_goal(session, goal, limit_s, "navigation")


def follow_goal(session: Session, goal, limit_s: float, what: str) -> None:
    """Follow a goal the robot's own stack runs (navigation, docking) until it ends; cancel it on any exit."""
    deadline = time.monotonic() + limit_s
    try:
        while True:
            pose = session.pose()
            session.check()
            outcome = session.link.goal_outcome(goal, pose)
            if outcome == "succeeded":
                return
            if outcome in ("failed", "cancelled"):
                raise StepFailed(f"{session.robot.name}: {what} reports the goal {outcome}")
            if time.monotonic() > deadline:
                raise StepFailed(f"{session.robot.name}: {what} did not finish within {limit_s:.0f} s")
    except BaseException:
        session.link.halt(goal)
        raise


def travel_time(distance: float, turn: float, limits: motion.Limits, factor: float) -> float:
    """A generous limit for a leg: three times the ideal time plus slack."""
    return 3 * (distance / (limits.linear * factor) + turn / (limits.angular * factor)) + 10


def run_step(session: Session, step: dict) -> str:
    """Run one step with its action's handler (fleetcore/actions.py); return a few words on what was done."""
    checked = Step.from_dict(step)
    if checked.spec.handler is None:
        raise StepFailed(f"{session.robot.name}: {checked.action!r} is not something the executor runs")
    return import_string(checked.spec.handler)(session, checked)


def advance(execution: Execution, index: int) -> None:
    Execution.objects.filter(pk=execution.pk).update(step_index=index)
