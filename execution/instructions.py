"""Submitting an instruction: interpret it, store it and hand it to execution (or say why not), in one transaction.

The text is read once (`interpreter.service.read`) into the typed Interpretation (fleetcore.interpretation), which
says whether it is a stop and which robots it names. Stop instructions ("stop", "halt everything", "stop husky")
do not queue: read with the grammar the process has (no Redis on the way), a zero velocity is published from an
event loop and the robots' stop flags raised before any database write (execution.fast_stop, as the STOP button does), then execution.control.stop checks, stops again,
cancels what was queued and audits; a database or Redis that fails meanwhile is said in the outcome, never raised. Everything else is
checked against the step contract (fleetcore.steps) and becomes one Execution per robot, run by the executor
process that owns the robot (execution/executor.py: woken after the commit). A database that fails midway leaves no row behind.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from django.db import transaction
from django.utils import timezone

import live
from access import holds
from access.leases import ControlRefused
from access.roles import can_control
from audit import records as audit
from execution import dispatch, fast_stop, queries, queues, tasklist
from execution.bookkeeping import brief_lock_wait
from execution.models import Instruction
from fleetcore import faults
from fleetcore.interpretation import EVERY, Interpretation
from fleetcore.states import Event
from interpreter.service import read
from robots.models import Robot

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Reading:
    """A text read once: what it was understood as and, for a stop, the robots it stops (EVERY: all of them;
    None: no stop). Made once per text (`Reading.of`): the page's socket makes it for a stop's head start and
    hands it to `submit`, which neither parses the text nor asks "is it a stop?" again."""

    understood: Interpretation
    stops: set[str] | str | None

    @classmethod
    def of(cls, parse: Interpretation | dict) -> Reading:
        understood = Interpretation.from_dict(parse)
        return cls(understood, _stop_names(understood) if understood.is_stop else None)


def submit(
    text: str,
    user,
    source: str = "console",
    parse: Reading | Interpretation | dict | None = None,
    answer_to=None,
    robot_ids: list[int] | None = None,
    cause: str = "",
) -> Instruction:
    """Receive, interpret and (when understood and allowed) dispatch one instruction.

    parse: the text as already read (the page's socket read it for a stop's head start: `understand`), or an
    instruction the portal wrote (Interpretation.direct: click-to-move, schedules; or its stored form); else
    the text is read here, once.
    robot_ids: the robots selected on the page; a step whose text names no robot goes to them.
    cause: why the system sends it (no user), kept with it: "make way for husky, instruction #14 by admin".
    """
    text = (text or "").strip()
    if not text:
        raise ValueError("An instruction needs some text.")
    reading = (
        parse if isinstance(parse, Reading) else Reading.of(parse if parse is not None else _interpret(text))
    )
    if reading.stops is not None and (user is None or can_control(user)):
        return _stop_first(text, user, source, reading, answer_to, robot_ids)
    # the pushes its commit sends (the instruction, each robot's task list) go in one hand-over once it is done:
    # from a web server's request thread each was a hand-over to the server's loop and a wait, a tenth of a
    # second for an instruction to 50 robots
    with live.together(), transaction.atomic():
        instruction = _store_and_dispatch(text, user, source, reading, answer_to, robot_ids, cause)
    if reading.understood.cancels and instruction.status == Instruction.Status.RECEIVED:
        return _cancel(
            instruction, reading.understood, user
        )  # after the commit: the runner it stops settles it
    return instruction


def _stop_first(text: str, user, source: str, reading: Reading, answer_to, robot_ids) -> Instruction:
    """The zeros before any database write, like the button; then the instruction is stored and control.stop
    answers. A database that cannot take the row leaves the stop done and said: an unsaved instruction whose
    outcome names what could not be recorded (a failure that is no store's is raised, after the zeros)."""
    fast_stop.stop_blocking(reading.stops)
    try:
        with brief_lock_wait(), transaction.atomic():
            return _store_and_dispatch(text, user, source, reading, answer_to, robot_ids)
    except Exception as exc:
        words = faults.store_fault(exc)
        if words is None:
            raise
        log.warning("stop %r not stored (%s); the robots are stopped", text, words)
        return _unrecorded_stop(text, user, source, reading, words)


def _unrecorded_stop(text: str, user, source: str, reading: Reading, words: str) -> Instruction:
    """The stop again, past the database that failed (zeros and flags), as an instruction that was not saved."""
    from execution.control import stop  # read when called: the socket's tests stand in a control module

    understood, names = reading.understood, reading.stops
    if names == EVERY:
        names = set(Robot.objects.values_list("name", flat=True))
    results = stop(sorted(names), user, source=source, database_fault=words)
    reached = "; ".join(f"{name}: {why}" for name, why in sorted(results.items()))
    now = timezone.now()
    return Instruction(
        text=text,
        user=user,
        source=source,
        type=understood.type,
        parse=understood.to_dict(),
        status=Instruction.Status.SUCCEEDED,
        outcome=f"{reached or 'no robot'}.{results.note()}",
        received_at=now,
        interpreted_at=now,
        finished_at=now,
    )


def _store_and_dispatch(
    text: str, user, source: str, reading: Reading, answer_to, robot_ids=None, cause: str = ""
) -> Instruction:
    understood = reading.understood
    instruction = Instruction.objects.create(
        text=text, user=user, source=source, answer_to=answer_to, cause=cause[:255]
    )
    audit.record(user, "instruct", text[:255], instruction=instruction.pk, source=source)
    if answer_to is not None:
        close_dialog(answer_to, "answered", answered_by=instruction)
    instruction.parse = understood.to_dict()
    instruction.type = understood.type
    instruction.interpreted_at = timezone.now()
    instruction.save(update_fields=["parse", "type", "interpreted_at"])
    if understood.needs_user:
        return _ask(instruction, understood)
    if reading.stops is not None:
        return _stop(instruction, reading.stops, user)
    if understood.cancels:
        return instruction  # carried out by submit after the commit (execution.tasklist)
    if understood.releases:
        return _release(instruction, understood, user)
    if not understood.steps:  # "don't move tiago": understood, and nothing is to be done
        return _close(instruction, Instruction.Status.SUCCEEDED, understood.reason or "Nothing to do.")
    if understood.is_question:  # answered now from live state; nothing moves, nothing queues
        try:
            words, about = queries.answer(understood, robot_ids)
        except dispatch.Refused as exc:
            return _close(instruction, Instruction.Status.REFUSED, str(exc))
        instruction.robots.set(about)
        return _close(instruction, Instruction.Status.SUCCEEDED, words)
    try:
        plan = dispatch.plan(
            understood, user, check_schedule=source != "schedule", selected=robot_ids, source=source
        )
        executions = dispatch.dispatch(instruction, plan)
        queues.push_queues([execution.robot_id for execution in executions])  # the task lists, after commit
    except dispatch.NoneFree as exc:
        instruction = dispatch.wait(instruction, str(exc))
    except (dispatch.Refused, ControlRefused) as exc:
        return _close(instruction, Instruction.Status.REFUSED, str(exc))
    live.instruction(instruction)
    return instruction


def understand(text: str) -> Reading:
    """The text read once, with the robots it stops (EVERY for "stop", "halt everything"; None: no stop).

    For the page's socket: it raises the flags and sends the zeros from its event loop first, then hands the
    same reading to `submit` (the text is not parsed again, nor its stop's robots looked up again).
    """
    return Reading.of(_interpret((text or "").strip()))


def _interpret(text: str) -> Interpretation:
    return read(text)


def _close(instruction: Instruction, status: str, outcome: str) -> Instruction:
    instruction.status, instruction.outcome = status, outcome
    if status in Instruction.FINAL:
        instruction.finished_at = timezone.now()
    instruction.save(update_fields=["status", "outcome", "finished_at"])
    live.instruction(instruction)
    return instruction


def _ask(instruction: Instruction, understood: Interpretation) -> Instruction:
    """The person must answer: the robots named (and ready) wait in the dialog state."""
    question = understood.question or understood.reason or "Please rephrase the instruction."
    for robot in Robot.objects.filter(name__in=understood.named(), state=Robot.State.READY):
        Robot.objects.transition(robot.pk, Event.ASK, question[:255], instruction)
    return _close(instruction, Instruction.Status.NEEDS_USER, question)


def close_dialog(instruction: Instruction, reason: str, answered_by: Instruction | None = None) -> None:
    """Bring the robots waiting on this instruction's question back to ready; close the question.

    Answered (answered_by: the instruction the answer ran as), the question keeps its type (V for a word the
    interpreter did not know) and says which instruction ran; else it is cancelled with the reason.
    """
    for robot in Robot.objects.filter(
        transitions__instruction=instruction, state=Robot.State.DIALOG
    ).distinct():
        Robot.objects.transition(robot.pk, Event.DONE, reason, instruction)
    if instruction.status != Instruction.Status.NEEDS_USER:
        return
    if answered_by is not None:
        _close(
            instruction,
            Instruction.Status.ANSWERED,
            f"{instruction.outcome} Answered: ran as #{answered_by.pk}.",
        )
    else:
        _close(instruction, Instruction.Status.CANCELLED, f"{instruction.outcome} ({reason})")


def _stop_names(understood: Interpretation) -> set[str] | str:
    """The robots a stop (or release) names, or EVERY (Interpretation.stop_names; the fleet read only for a
    choice by kind or exclusion)."""
    return understood.stop_names(lambda: Robot.objects.values_list("name", "model", "drive"))


def _stop(instruction: Instruction, names: set[str] | str, user) -> Instruction:
    from execution.control import stop  # read when called: the socket's tests stand in a control module

    chose = ""
    if names == EVERY:
        names = set(Robot.objects.values_list("name", flat=True))
        chose = f"every robot stopped ({len(names)}: a stop that names no robot stops them all). "
    if not names:
        return _close(instruction, Instruction.Status.REFUSED, "No robot is registered.")
    try:
        results = stop(sorted(names), user, source=instruction.source)
    except (ControlRefused, ValueError) as exc:
        return _close(instruction, Instruction.Status.REFUSED, str(exc))
    instruction.robots.set(Robot.objects.filter(name__in=names))
    instruction.dispatched_at = instruction.first_command_at = timezone.now()
    instruction.save(update_fields=["dispatched_at", "first_command_at"])
    failed = {name: why for name, why in results.items() if why != "stopped"}
    outcome = chose + "; ".join(f"{name}: {why}" for name, why in sorted(results.items()))
    note = results.note() if hasattr(results, "note") else ""  # what of the stop's bookkeeping failed
    outcome += f".{note}" if note else ""
    return _close(instruction, Instruction.Status.FAILED if failed else Instruction.Status.SUCCEEDED, outcome)


def _cancel(instruction: Instruction, understood: Interpretation, user) -> Instruction:
    """ "cancel #12", "cancel husky's instruction": take one instruction back (execution.tasklist)."""
    step = next(step for step in understood.steps if step.get("action") == "cancel")
    try:
        target = tasklist.named(step)
        done = tasklist.cancel_instruction(target, user, source=instruction.source)
    except (tasklist.NothingToCancel, ControlRefused) as exc:
        return _close(instruction, Instruction.Status.REFUSED, str(exc))
    instruction.robots.set(done.robots.all())
    return _close(instruction, Instruction.Status.SUCCEEDED, tasklist.said(done))


def _release(instruction: Instruction, understood: Interpretation, user) -> Instruction:
    """ "release tiago" ("release": every robot held): let robots a stop holds move again (access.holds)."""
    names = _stop_names(understood)
    held = Robot.objects.filter(held_at__isnull=False)
    robots = list(held if names == EVERY else Robot.objects.filter(name__in=names))
    missing = set() if names == EVERY else set(names) - {robot.name for robot in robots}
    if missing:
        return _close(
            instruction, Instruction.Status.REFUSED, f"No robot named {', '.join(sorted(missing))}."
        )
    try:
        released = holds.release_by(user, robots) if user is not None else holds.release(robots, None)
    except ControlRefused as exc:
        return _close(instruction, Instruction.Status.REFUSED, str(exc))
    instruction.robots.set(robots)
    words = [f"released {name} ({was})" for name, was in released.items()]
    words += [f"{robot.name} was not held" for robot in robots if robot.name not in released]
    return _close(instruction, Instruction.Status.SUCCEEDED, "; ".join(words) or "No robot is held.")


def on_make_way_asked(sender, robot: Robot, asked: str, cause: str, **kwargs) -> str | None:
    """Submit the make_way instruction traffic asks for (execution.signals.make_way_asked) as the system's (no
    user, source "traffic"): the robot's hold, lease, schedule and state are checked as for any automatic
    instruction (execution.dispatch). The words of its refusal, or None when it was taken."""
    parse = Interpretation.for_robots([asked], "make_way", f"make way for {robot.name}")
    sent = submit(f"{asked} make way for {robot.name}", None, source="traffic", parse=parse, cause=cause)
    return sent.outcome if sent.status == "refused" else None
