"""Run executions: each robot's queue drained by whoever holds its Redis lock, one execution at a time.

Dispatch wakes each robot of an instruction (execution.executor.wake); the executor process that owns the
robot runs `drain_robot` as one asyncio task on its loop, next to the robot's link. A drain that gets the
robot's lock runs the robot's queued executions in order (the instruction's own and any queued behind it,
whoever sent them); one that does not get it leaves them queued for the holder. A preempting execution is
named in the robot's preempt flag: the holder interrupts the current execution (back in the queue, at the
step it reached) and runs the preemptor next. The database is reached through the process's blocking pool
(execution.blocking); the lock is kept, and the flags read, by the process's board (execution.board).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from django.db.models import F
from django.utils import timezone

import alerts
import live
from access import holds
from execution import blocking, board, coordination, queues
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


SHUT_DOWN = "stopped: its executor was shut down"


async def drain_robot(robot_id: int) -> bool:
    """Run the robot's waiting executions under its lock; False if another runner holds it or none waited.

    It is started because work waits (a wake-up, the sweep), so it takes the lock first and looks for the work
    under it; after a run it looks again before taking the lock anew (work queued while it ran, whose wake-up
    found the robot's task still running). Each call through the blocking pool waits behind every other robot's
    in the process: an executor starting 50 robots at once took 2 to 5 s to their first command with twice as
    many calls per robot (bench.cluster, "under instructions")."""
    ran, kept = False, board.of_loop()
    while True:
        lease = await kept.take(coordination.RobotLock(robot_id))
        if lease is None:
            return ran
        found, preferred = False, None
        try:
            while lease.held and (
                execution := await while_resting(lease, next_execution, robot_id, preferred)
            ):
                found = ran = True
                lease.beat()
                preferred = await run_execution(execution, lease)
        finally:
            await asyncio.shield(kept.give_back(lease))
        if not found or not await blocking.call(waiting, robot_id):
            return ran


def next_execution(robot_id: int, preferred: int | None = None) -> Execution | None:
    """The preemptor if one is named, else the first in the robot's queue (oldest, unless a person moved it);
    with its robot, and its instruction's status as `instruction_status` (what the claim needs)."""
    _, flagged = coordination.flags(robot_id)
    queued = (
        Execution.objects.filter(robot_id=robot_id, status__in=WAITING)
        .select_related("robot")
        .annotate(instruction_status=F("instruction__status"))
    )
    for pk in (preferred, flagged):
        if pk is not None:
            found = queued.filter(pk=pk).first()
            if found is not None:
                return found
    return queued.order_by("queued_at", "pk").first()


def waiting(robot_id: int) -> bool:
    """Whether the robot has work waiting (a drain's look after its run, before it takes the lock anew)."""
    return Execution.objects.filter(robot_id=robot_id, status__in=WAITING).exists()


# A call through the blocking pool while the robot rests (its start, between steps, its end) keeps the robot's lock
# this long, not LIVELY_S: a stop-all ends every robot of an executor at once, and with 250 robots' ends queued in
# its pool some waited past LIVELY_S, their locks lapsed, and the watchdog called a robot a person had stopped
# "executor lost" (bench.cluster at 500 robots). Nothing is commanded meanwhile; a call that never returns still
# lets the lock lapse for the watchdog, this much later.
RESTING_WAIT_S = 60.0


async def while_resting(lease: board.Lease, fn, /, *args):
    """fn(*args) through the blocking pool, the lease kept alive for RESTING_WAIT_S meanwhile (see above)."""
    lease.beat(RESTING_WAIT_S)
    try:
        return await blocking.call(fn, *args)
    finally:
        lease.beat()


STARTING = (Instruction.Status.QUEUED, Instruction.Status.RECEIVED)  # none of its robots runs yet


def claim(execution: Execution, token: str) -> bool:
    """Mark the execution running under this token, unless someone else did first (conditional update); the
    instruction running with its first robot's claim, pushed then (each claim pushes its robot's task list)."""
    dispatched = execution.dispatched_at or timezone.now()
    won = Execution.objects.filter(pk=execution.pk, status__in=WAITING).update(
        status=Execution.Status.RUNNING, worker=token, dispatched_at=dispatched
    )
    if won:
        execution.status, execution.worker, execution.dispatched_at = (
            Execution.Status.RUNNING,
            token,
            dispatched,
        )
        started = getattr(execution, "instruction_status", STARTING[0]) in STARTING and (
            Instruction.objects.filter(pk=execution.instruction_id, status__in=STARTING).update(
                status=Instruction.Status.RUNNING
            )
        )
        if started:
            _push_instruction(execution.instruction_id, [execution.robot_id])
        else:
            queues.push_robot_queues([execution.robot])
    return bool(won)


async def run_execution(execution: Execution, lease: board.Lease) -> int | None:
    """Run one execution from its current step; return the execution that preempted it, if any. Its task
    cancelled (the executor shuts down), the robot is halted and the execution ends saying so."""
    # a failure before its claim is raised: it stays queued
    begun = await while_resting(lease, _begin, execution, lease.token)
    if begun is None:
        return None  # not claimed: another runner's, or a stop holds the robot back (nothing to record)
    outcome, words, preemptor, shut_down = "succeeded", [], None, False
    link = session = None
    try:
        if isinstance(begun, Exception):
            raise begun  # claimed, but its link could not be made: the run fails with the reason
        link = begun
        await link.open()
        session = Session(execution, link, lease)
        await lease.fresh()  # its cancel flag read before anything moves (a cancel that came while it queued)
        for index in range(execution.step_index, len(execution.steps)):
            words.append(await run_step(session, execution.steps[index]))
            await while_resting(lease, advance, execution, index + 1)  # a step ends with its robot halted
    except asyncio.CancelledError:
        outcome, shut_down = "failed", True
        words.append(SHUT_DOWN)
    except Interrupted as exc:
        outcome, preemptor = exc.outcome, exc.preemptor
        words.append(exc.reason)
    except LinkLost as exc:  # it may still be driving on our last command: a zero as soon as it is back
        await blocking.call(links.owe_zero, [execution.robot_id])
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
        lease.beat(RESTING_WAIT_S)  # halted from here on: what is left is bookkeeping, under the lock
        await asyncio.shield(_halt(link))
        if session is not None:
            await asyncio.shield(session.stamped())
    said = "; ".join(words)
    ending = while_resting(lease, _end, execution, lease.token, outcome, said, words[-1:])
    recorded = await asyncio.shield(ending)
    if shut_down:
        raise asyncio.CancelledError
    return preemptor if recorded else None


def _begin(execution: Execution, token: str) -> RobotLink | Exception | None:
    """Clear the execution's preempt flag and claim it (unless a stop holds the robot back), then build its
    robot's link (its bindings read), in one call to the blocking pool: None when it does not run; else the
    link, or why it could not be made (no move topic bound, a database gone after the claim), for the run to
    fail with. A failure before the claim is raised: the execution stays queued, for the sweep."""
    coordination.clear_preempt(execution.robot_id, execution.pk)
    if _held_back(execution) or not claim(execution, token):
        return None
    try:
        return RobotLink(execution.robot)
    except Exception as exc:  # claimed: recorded as the run's failure, never left running
        return exc


def _end(execution: Execution, token: str, outcome: str, said: str, last: list[str]) -> bool:
    """Record how the execution ended, unless another runner took it since; False when the database refused
    (the end is kept for the sweep). A failure is one step_failed alert (a stall's robot_stuck alert, if it
    raised one, becomes this: one event, one alert)."""
    try:
        ended = finish(execution, token, outcome, said)
    except Exception as exc:
        _unrecorded(execution, exc, outcome, said)
        return False
    if ended and outcome == "failed":
        words = f"instruction #{execution.instruction_id}: {last[0]}"
        alerts.raise_alert("step_failed", execution.robot, words, execution.event)
    return True


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
    if execution.robot.held_at is None:  # as read with the execution, under the robot's lock
        return False
    robot = Robot.objects.filter(pk=execution.robot_id).select_related("held_by").first()
    if robot is None or robot.held_at is None:
        return False
    instruction = Instruction.objects.get(pk=execution.instruction_id)
    if not holds.is_automatic(instruction.source) and execution.created_at > robot.held_at:
        return False
    Execution.objects.filter(pk=execution.pk, status__in=WAITING).update(
        status=Execution.Status.CANCELLED, finished_at=timezone.now(), error=holds.refusal(robot)[:2000]
    )
    settle(execution.instruction_id, changed=execution.robot_id)
    return True


async def _halt(link: RobotLink | None) -> None:
    """The final zero, and the robot's last pose kept where the fleet reads it (robots.poses): the step stored it
    only every STORE_POSE_EVERY while it ran, so without this the portal could place a robot that has just
    arrived up to half a second of driving short of where it stands (where no pose hub runs, or one lags),
    and give a robot sent "to tiago" a spot on the far side of tiago's doorway."""
    if link is None:
        return
    try:
        await link.halt()
    except Exception:
        log.warning("%s: could not publish the final zero velocity", link.robot.name)
    if link.poses.value is not None:
        try:
            await blocking.call(pose_store.store_pose, link.robot.pk, link.poses.value)
        except Exception:  # the cache is away: the pose hub (or the next step) keeps it later
            log.warning("%s: its last pose could not be kept", link.robot.name, exc_info=True)
    with contextlib.suppress(Exception):  # a link that is down has nothing to release
        await link.close()


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
        settle(execution.instruction_id, changed=execution.robot_id)
    return bool(won)


def settle(instruction_id: int, changed: int | None = None) -> None:
    """Give the instruction its final status once every robot's share has one, pushed with every robot's task
    list; until then push the task list of the robot whose share `changed` (a claim or an end changes that
    robot's list only, and not the instruction: its status and words change with its first claim and its end).
    Whether any share is still open is one query: reading every share (and its robot) at each robot's end made
    an instruction to 50 robots read 2,500 rows, a fifth of its executor's time (py-spy)."""
    shares = Execution.objects.filter(instruction_id=instruction_id)
    if shares.exclude(status__in=FINAL).exists() or not shares.exists():
        if changed is not None:
            queues.push_queues([changed])
        return
    rows = list(shares.values_list("robot_id", "robot__name", "status", "error", "outcome"))
    found = {status for _, _, status, _, _ in rows}
    if Execution.Status.FAILED in found:
        status = Instruction.Status.FAILED
    elif Execution.Status.CANCELLED in found:
        status = Instruction.Status.CANCELLED
    else:
        status = Instruction.Status.SUCCEEDED
    outcome = "; ".join(
        outcomes.robot_line(name, state, error or said) for _, name, state, error, said in rows
    )
    chosen = Instruction.objects.filter(pk=instruction_id).values_list("outcome", flat=True).first()
    outcome = f"{chosen}. {outcome}" if chosen else outcome  # who was chosen and why (execution.dispatch)
    Instruction.objects.filter(pk=instruction_id).exclude(status__in=Instruction.FINAL).update(
        status=status, finished_at=timezone.now(), outcome=outcome[:4000]
    )
    _push_instruction(instruction_id, [robot_id for robot_id, *_ in rows])


def _push_instruction(instruction_id: int, robot_ids: list[int]) -> None:
    """The instruction to the pages, with the task lists of these robots. A robot's claim or end changes its own
    list only: pushing every robot's on each of them made an instruction to N robots cost N x N task lists, which
    starved an executor starting 50 robots until their locks lapsed."""
    instruction = Instruction.objects.filter(pk=instruction_id).first()
    if instruction is not None:
        live.instruction(instruction)
        queues.push_queues(robot_ids)
