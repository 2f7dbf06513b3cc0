"""The task list's cancel: one instruction taken back (each robot's queue and its order: execution/queues.py).

A cancel takes one instruction back, whoever sent it (access.leases.check_cancel says who may): its waiting
executions are cancelled at once; a running one is flagged (coordination.request_cancel, keyed by the execution,
so nothing else the robot does is touched) and its runner stops it on its next tick, halting the robot and
cancelling its navigation goal as on any exit; a zero goes out from here too. The instruction settles as
cancelled with who cancelled it, and the cancel is audited. Unlike a stop, a cancel holds no robot: what
waits behind the instruction runs next.
"""

from __future__ import annotations

import logging
import time

from django.utils import timezone

import live
from access.leases import check_cancel
from audit import records as audit
from execution import coordination
from execution.link import publish_zero
from execution.models import Execution, Instruction
from execution.queues import running_first
from execution.runner import WAITING, settle
from fleetcore.choice import NAMES, ChoiceError, RobotChoice
from fleetcore.states import Event
from robots.models import Robot

log = logging.getLogger(__name__)

CANCEL_WAIT_S = 3.0  # how long a cancel waits for a running execution's runner to stop it (then it answers)


class NothingToCancel(ValueError):
    """The instruction is unknown or already over; the message says which, in words."""


def who(user) -> str:
    return getattr(user, "username", None) or "the system"


def cancel_instruction(
    instruction, user, source: str = "console", wait_s: float = CANCEL_WAIT_S
) -> Instruction:
    """Cancel one instruction (an Instruction or its id): its waiting executions at once, a running one stopped
    with its robot brought to rest; settled as cancelled by `user` and audited. ControlRefused when the user may
    not, NothingToCancel when it is already over. Returns the instruction as it stands after at most wait_s."""
    instruction = _open_instruction(instruction)
    rows = list(instruction.executions.select_related("robot"))
    robots = [row.robot for row in rows]
    if user is not None:
        check_cancel(user, instruction.user, robots)
    words = f"cancelled by {who(user)}"
    was = instruction.status
    waiting = _cancel_waiting([row.pk for row in rows], words)
    running = list(Execution.objects.filter(instruction=instruction, status=Execution.Status.RUNNING))
    _stop_running(running, words)
    if not rows:  # a question, or an instruction waiting for a free robot: nothing runs it yet
        _close_unrun(instruction, words)
    audit.record(
        user, "cancel", f"#{instruction.pk}", source=source, was=was,
        robots=[robot.name for robot in robots], running=[row.robot.name for row in running], waiting=waiting,
    )  # fmt: skip
    settle(instruction.pk)
    _wait_settled(instruction, wait_s if running else 0)
    instruction.refresh_from_db()
    return instruction


def _open_instruction(instruction) -> Instruction:
    if not isinstance(instruction, Instruction):
        found = Instruction.objects.filter(pk=instruction).first()
        if found is None:
            raise NothingToCancel(f"There is no instruction #{instruction}.")
        instruction = found
    if instruction.is_final:
        raise NothingToCancel(f"Instruction #{instruction.pk} is already over ({instruction.status}).")
    return instruction


def _cancel_waiting(execution_ids: list[int], words: str) -> int:
    """Cancel the executions of these that wait (a conditional update: one claimed meanwhile runs, and is
    stopped next)."""
    return Execution.objects.filter(pk__in=execution_ids, status__in=WAITING).update(
        status=Execution.Status.CANCELLED, finished_at=timezone.now(), error=words
    )


def _stop_running(running: list[Execution], words: str) -> None:
    """Flag the running executions cancelled (their runners halt the robots and settle them), then a zero now."""
    if not running:
        return
    coordination.request_cancel([row.pk for row in running], words)
    for row in running:
        try:
            publish_zero(row.robot)
        except Exception as exc:  # the runner's own halt still comes on its next tick
            log.warning("cancel: zero to %s failed: %s", row.robot.name, exc)


def _close_unrun(instruction: Instruction, words: str) -> None:
    """A question or an instruction waiting for a robot: cancelled as it is; robots asked back to ready."""
    for robot in Robot.objects.filter(
        transitions__instruction=instruction, state=Robot.State.DIALOG
    ).distinct():
        Robot.objects.transition(robot.pk, Event.DONE, words, instruction)
    outcome = f"{instruction.outcome} ({words})" if instruction.outcome else words
    Instruction.objects.filter(pk=instruction.pk).exclude(status__in=Instruction.FINAL).update(
        status=Instruction.Status.CANCELLED, finished_at=timezone.now(), outcome=outcome[:4000]
    )
    live.instruction(Instruction.objects.get(pk=instruction.pk))


def _wait_settled(instruction: Instruction, wait_s: float) -> None:
    """Wait (bounded) for the runners to settle what they were running; the answer then says how it ended."""
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        if not Instruction.objects.filter(pk=instruction.pk).exclude(status__in=Instruction.FINAL).exists():
            return
        time.sleep(0.05)


def named(step: dict) -> Instruction:
    """The instruction a cancel step names: its number ("cancel #12"), else what its one robot runs now or waits
    for first ("cancel husky's instruction"); NothingToCancel says why there is none."""
    if step.get("instruction") is not None:
        return _open_instruction(step["instruction"])
    try:
        choice = RobotChoice.of(step.get("robots"))
    except ChoiceError:
        choice = None
    if choice is None or choice.mode != NAMES or len(choice.names) != 1:
        raise NothingToCancel("Say which instruction: 'cancel #12', or 'cancel husky's instruction'.")
    (name,) = choice.names
    row = (
        Execution.objects.filter(robot__name=name, status__in=(Execution.Status.RUNNING, *WAITING))
        .select_related("instruction")
        .order_by(running_first(), "queued_at", "pk")
        .first()
    )
    if row is None:
        raise NothingToCancel(f"{name} has no instruction running or waiting.")
    return row.instruction


def said(instruction: Instruction) -> str:
    """The cancel's answer: "#12 (move husky to A): cancelled. husky: cancelled (cancelled by ada)"."""
    head = f"#{instruction.pk} ({instruction.text[:80]})"
    if instruction.is_final:
        return f"{head}: {instruction.status}. {instruction.outcome}".strip()
    return f"{head}: cancelling; its robot is being stopped."
