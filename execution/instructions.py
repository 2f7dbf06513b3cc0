"""Submitting an instruction: interpret it, store it and hand it to execution (or say why not), in one transaction.

Stop instructions ("stop", "halt everything", "stop husky") do not queue: the robots' stop flags are raised and a
zero velocity published from an event loop before any database write (execution.fast_stop, as the STOP button
does), then execution.control.stop checks, stops again, cancels what was queued and audits. Everything else is
checked against the step contract (fleetcore.steps) and becomes one Execution per robot, run by the Celery
workers (execution.tasks.drain_robot, one per robot). A database that fails midway leaves no row behind.
"""

from __future__ import annotations

from django.db import transaction
from django.utils import timezone

import live
from access.leases import ControlRefused
from access.roles import can_control
from audit import records as audit
from execution import dispatch, fast_stop, queries
from execution.models import Instruction
from fleetcore.states import Event
from robots.models import Robot


def submit(
    text: str,
    user,
    source: str = "console",
    parse: dict | None = None,
    answer_to=None,
    robot_ids: list[int] | None = None,
) -> Instruction:
    """Receive, interpret and (when understood and allowed) dispatch one instruction.

    parse: an interpreter result given by the caller (schedules, tests); else the interpreter is asked.
    robot_ids: the robots selected on the page; a step whose text names no robot goes to them.
    """
    text = (text or "").strip()
    if not text:
        raise ValueError("An instruction needs some text.")
    result = parse if parse is not None else _interpret(text)
    if _is_stop(result) and (user is None or can_control(user)):
        fast_stop.stop_blocking(_stop_names(result))  # before any database write, like the button
    with transaction.atomic():
        return _store_and_dispatch(text, user, source, result, answer_to, robot_ids)


def _store_and_dispatch(text: str, user, source: str, result: dict, answer_to, robot_ids=None) -> Instruction:
    instruction = Instruction.objects.create(text=text, user=user, source=source, answer_to=answer_to)
    audit.record(user, "instruct", text[:255], instruction=instruction.pk, source=source)
    if answer_to is not None:
        close_dialog(answer_to, "answered", answered_by=instruction)
    instruction.parse = result
    instruction.type = result.get("type", "")
    instruction.interpreted_at = timezone.now()
    instruction.save(update_fields=["parse", "type", "interpreted_at"])
    if result.get("needs_user") or not result.get("valid", True):
        return _ask(instruction, result)
    if _is_stop(result):
        return _stop(instruction, result, user)
    if not result.get("steps"):  # "don't move tiago": understood, and nothing is to be done
        return _close(instruction, Instruction.Status.SUCCEEDED, result.get("reason") or "Nothing to do.")
    if queries.is_question(result):  # answered now from live state; nothing moves, nothing queues
        try:
            words, about = queries.answer(result, robot_ids)
        except dispatch.Refused as exc:
            return _close(instruction, Instruction.Status.REFUSED, str(exc))
        instruction.robots.set(about)
        return _close(instruction, Instruction.Status.SUCCEEDED, words)
    try:
        plan = dispatch.plan(result, user, check_schedule=source != "schedule", selected=robot_ids)
        dispatch.dispatch(instruction, plan)
    except dispatch.NoneFree as exc:
        instruction = dispatch.wait(instruction, str(exc))
    except (dispatch.Refused, ControlRefused) as exc:
        return _close(instruction, Instruction.Status.REFUSED, str(exc))
    live.instruction(instruction)
    return instruction


def stop_names(text: str) -> set[str] | str | None:
    """The robots a typed stop names ("all" for "stop", "halt everything"); None when the text is no stop.

    For callers on an event loop (the page's socket) that raise the flags and send the zeros there first.
    """
    result = _interpret((text or "").strip()) if (text or "").strip() else {}
    return _stop_names(result) if _is_stop(result) else None


def _interpret(text: str) -> dict:
    from interpreter.service import interpret

    return interpret(text)


def _close(instruction: Instruction, status: str, outcome: str) -> Instruction:
    instruction.status, instruction.outcome = status, outcome
    if status in Instruction.FINAL:
        instruction.finished_at = timezone.now()
    instruction.save(update_fields=["status", "outcome", "finished_at"])
    live.instruction(instruction)
    return instruction


def _ask(instruction: Instruction, result: dict) -> Instruction:
    """The person must answer: the robots named (and ready) wait in the dialog state."""
    question = result.get("question") or result.get("reason") or "Please rephrase the instruction."
    for step in result.get("steps", []):
        names = step.get("robots")
        if isinstance(names, list):
            for robot in Robot.objects.filter(name__in=names, state=Robot.State.READY):
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


def _is_stop(result: dict) -> bool:
    return any(step.get("action") == "stop" for step in result.get("steps", []))


def _stop_names(result: dict) -> set[str] | str:
    """The robots a stop instruction names, or "all" ("stop", "stop all", "halt everything"); "stop every robot
    except husky" names the others (one query, only for a subject chosen by kind or exclusion)."""
    names = set()
    for step in result.get("steps", []):
        robots = step.get("robots")
        if isinstance(robots, dict) and (robots.get("except") or robots.get("model")):
            rows = Robot.objects.only("name", "model", "drive")
            names |= {robot.name for robot in rows if dispatch.matches(robot, robots)}
            continue
        if not isinstance(robots, list) or not robots:
            return "all"
        names |= set(robots)
    return names


def _stop(instruction: Instruction, result: dict, user) -> Instruction:
    from execution.control import stop

    names = _stop_names(result)
    if names == "all":
        names = set(Robot.objects.values_list("name", flat=True))
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
    outcome = "; ".join(f"{name}: {why}" for name, why in sorted(results.items()))
    return _close(instruction, Instruction.Status.FAILED if failed else Instruction.Status.SUCCEEDED, outcome)
