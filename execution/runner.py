"""Run executions: each robot's queue drained by whoever holds its Redis lock, one execution at a time.

Dispatch wakes each robot of an instruction with one Celery task (execution.tasks.drain_robot: the robot's
executor). A task that gets the robot's lock runs the robot's queued executions in order (the instruction's own
and any queued behind it, whoever sent them); a task that does not get it leaves its execution queued for the
holder. A preempting
execution is named in the robot's preempt flag: the holder interrupts the current execution (back in the
queue, at the step it reached) and runs the preemptor next.
"""

from __future__ import annotations

import logging

from django.db import close_old_connections
from django.utils import timezone

import alerts
import live
from access import holds
from execution import coordination, queues
from execution.handlers import run_step
from execution.link import LinkError, RobotLink
from execution.models import Execution, Instruction
from execution.steps import Interrupted, LinkLost, Session, StepFailed, advance
from fleetcore import faults, outcomes
from fleetcore.states import Event
from robots import links
from robots import poses as pose_store
from robots.models import Robot

log = logging.getLogger(__name__)

WAITING = (Execution.Status.QUEUED, Execution.Status.PREEMPTED)
FINAL = (Execution.Status.SUCCEEDED, Execution.Status.FAILED, Execution.Status.CANCELLED)
OUTCOME_EVENT = {
    "succeeded": Event.DONE,
    "cancelled": Event.STOP,
    "failed": Event.FAIL,
    "preempted": Event.PREEMPT,
}


def drain_robot(robot_id: int) -> bool:
    """Run the robot's waiting executions under its lock; False if another runner holds it."""
    ran = False
    while next_execution(robot_id) is not None:
        lock = coordination.RobotLock(robot_id)
        if not lock.acquire():
            return ran
        ran = True
        heartbeat = coordination.Heartbeat(lock).start()
        try:
            preferred = None
            while heartbeat.held and (execution := next_execution(robot_id, preferred)) is not None:
                heartbeat.beat()
                preferred = run_execution(execution, heartbeat)
        finally:
            heartbeat.stop()
            lock.release()
    return ran


def next_execution(robot_id: int, preferred: int | None = None) -> Execution | None:
    """The preemptor if one is named, else the first in the robot's queue (oldest, unless a person moved it)."""
    _, flagged = coordination.flags(robot_id)
    for pk in (preferred, flagged):
        if pk is not None:
            found = Execution.objects.filter(pk=pk, robot_id=robot_id, status__in=WAITING).first()
            if found is not None:
                return found
    return Execution.objects.filter(robot_id=robot_id, status__in=WAITING).order_by("queued_at", "pk").first()


def claim(execution: Execution, token: str) -> bool:
    """Mark the execution running under this token, unless someone else did first (conditional update)."""
    now = timezone.now()
    won = Execution.objects.filter(pk=execution.pk, status__in=WAITING).update(
        status=Execution.Status.RUNNING, worker=token, dispatched_at=execution.dispatched_at or now
    )
    if won:
        Instruction.objects.filter(
            pk=execution.instruction_id, status__in=(Instruction.Status.QUEUED, Instruction.Status.RECEIVED)
        ).update(status=Instruction.Status.RUNNING)
        _push_instruction(execution.instruction_id)
    return bool(won)


def run_execution(execution: Execution, heartbeat: coordination.Heartbeat) -> int | None:
    """Run one execution from its current step; return the execution that preempted it, if any."""
    close_old_connections()
    coordination.clear_preempt(execution.robot_id, execution.pk)
    if _held_back(execution):
        return None
    if not claim(execution, heartbeat.token):
        return None
    execution.refresh_from_db()
    outcome, words, preemptor = "succeeded", [], None
    link = None
    try:
        link = RobotLink(execution.robot).open()
        session = Session(execution, link, heartbeat)
        for index in range(execution.step_index, len(execution.steps)):
            words.append(run_step(session, execution.steps[index]))
            advance(execution, index + 1)
    except Interrupted as exc:
        outcome, preemptor = exc.outcome, exc.preemptor
        words.append(exc.reason)
    except LinkLost as exc:  # it may still be driving on our last command: a zero as soon as it is back
        links.owe_zero([execution.robot_id])
        outcome = "failed"
        words.append(str(exc))
    except (StepFailed, LinkError, ValueError) as exc:
        outcome = "failed"
        words.append(str(exc))
    except Exception as exc:  # a link error or a bug: the robot is stopped and the reason kept
        log.exception("execution %s failed", execution.pk)
        outcome = "failed"
        words.append(f"{type(exc).__name__}: {exc}")
    finally:
        _halt(link)
    try:
        ended = finish(execution, heartbeat.token, outcome, "; ".join(words))
    except Exception as exc:
        return _unrecorded(execution, exc, outcome, "; ".join(words))
    if ended and outcome == "failed":
        alerts.raise_alert(  # a stall's robot_stuck alert, if it raised one, becomes this: one event, one alert
            "step_failed",
            execution.robot,
            f"instruction #{execution.instruction_id}: {words[-1]}",
            execution.event,
        )
    return preemptor


def _unrecorded(execution: Execution, exc: Exception, outcome: str, words: str) -> None:
    """The database refused the end of an execution whose robot is halted: its words are kept in Redis, for the
    watchdog's sweep to record ("stopped; the database is locked ...") once the database takes writes again,
    never left "running" for good nor called "executor lost". A failure that is no store's is raised."""
    fault = faults.store_fault(exc)  # away or refusing: the end is kept for the sweep either way
    if fault is None:
        raise exc
    said = f"{words}; not recorded at once: {fault}" if outcome == "succeeded" else f"stopped; {fault}"
    log.warning("execution %s ended (%s) but not recorded: %s", execution.pk, words, fault)
    try:
        coordination.note_unrecorded_end(execution.pk, said)
    except Exception:  # both stores away: the sweep says "executor lost" once they are back
        log.exception("execution %s: its end could not be kept in Redis either", execution.pk)
    return None


def _held_back(execution: Execution) -> bool:
    """A robot a stop holds runs nothing it did not get after the stop from a person: an execution queued or
    preempted before the stop (a race with its cancel) or the system's is cancelled, with the hold's words."""
    robot = Robot.objects.filter(pk=execution.robot_id).select_related("held_by").first()
    if robot is None or robot.held_at is None:
        return False
    instruction = Instruction.objects.get(pk=execution.instruction_id)
    if not holds.is_automatic(instruction.source) and execution.created_at > robot.held_at:
        return False
    Execution.objects.filter(pk=execution.pk, status__in=WAITING).update(
        status=Execution.Status.CANCELLED, finished_at=timezone.now(), error=holds.refusal(robot)[:2000]
    )
    settle(execution.instruction_id)
    return True


def _halt(link: RobotLink | None) -> None:
    """The final zero, and the robot's last pose kept where the fleet reads it (robots.poses): the step stored it
    only every STORE_POSE_EVERY while it ran, so without this the portal could place a robot that has just
    arrived up to half a second of driving short of where it stands (where no pose hub runs, or one lags),
    and give a robot sent "to tiago" a spot on the far side of tiago's doorway."""
    if link is None:
        return
    try:
        link.halt()
    except Exception:
        log.warning("%s: could not publish the final zero velocity", link.robot.name)
    if link.poses.value is not None:
        try:
            pose_store.store_pose(link.robot.pk, link.poses.value)
        except Exception:  # the cache is away: the pose hub (or the next step) keeps it later
            log.warning("%s: its last pose could not be kept", link.robot.name, exc_info=True)
    link.close()


def finish(execution: Execution, token: str, outcome: str, words: str) -> bool:
    """Record the outcome (only if this token still runs it), move the robot to ready, settle the instruction."""
    ok = outcome in ("succeeded", "preempted")
    fields = {"status": outcome, "outcome": words[:2000], "error": "" if ok else words[:2000]}
    if outcome in FINAL:
        fields["finished_at"] = timezone.now()
    won = Execution.objects.filter(pk=execution.pk, status=Execution.Status.RUNNING, worker=token).update(
        **fields
    )
    if won:
        Robot.objects.transition(
            execution.robot_id, OUTCOME_EVENT[outcome], words[:255], execution.instruction_id
        )
        settle(execution.instruction_id, words if outcome == "succeeded" else "")
    return bool(won)


def settle(instruction_id: int, note: str = "") -> None:
    """Give the instruction its final status once every robot's share has one."""
    rows = list(Execution.objects.filter(instruction_id=instruction_id).select_related("robot"))
    if not rows or any(row.status not in FINAL for row in rows):
        return
    found = {row.status for row in rows}
    if Execution.Status.FAILED in found:
        status = Instruction.Status.FAILED
    elif Execution.Status.CANCELLED in found:
        status = Instruction.Status.CANCELLED
    else:
        status = Instruction.Status.SUCCEEDED
    outcome = "; ".join(
        outcomes.robot_line(row.robot.name, row.status, row.error or row.outcome) for row in rows
    )
    chosen = Instruction.objects.filter(pk=instruction_id).values_list("outcome", flat=True).first()
    outcome = f"{chosen}. {outcome}" if chosen else outcome  # who was chosen and why (execution.dispatch)
    Instruction.objects.filter(pk=instruction_id).exclude(status__in=Instruction.FINAL).update(
        status=status, finished_at=timezone.now(), outcome=outcome[:4000]
    )
    _push_instruction(instruction_id)


def _push_instruction(instruction_id: int) -> None:
    instruction = Instruction.objects.filter(pk=instruction_id).first()
    if instruction is not None:
        live.instruction(instruction)
        queues.push_queues(
            Execution.objects.filter(instruction_id=instruction_id).values_list("robot_id", flat=True)
        )
