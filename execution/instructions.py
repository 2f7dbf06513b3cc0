"""Submitting an instruction: store it, interpret it, and hand it to execution (or say why not).

Stop instructions ("stop", "stop all", "stop husky") do not queue: they are carried out in the calling
process before submit() returns (execution.control.stop). Everything else becomes one Execution per robot, run by
the Celery workers (execution.tasks.execute_instruction).
"""

from __future__ import annotations

from django.utils import timezone

import live
from access.leases import ControlRefused
from audit import records as audit
from execution import dispatch
from execution.models import Instruction
from fleetcore.states import Event
from robots.models import Robot


def submit(
    text: str, user, source: str = "console", parse: dict | None = None, answer_to=None
) -> Instruction:
    """Receive, interpret and (when understood and allowed) dispatch one instruction.

    parse: an interpreter result given by the caller (schedules, tests); else the interpreter is asked.
    """
    text = (text or "").strip()
    if not text:
        raise ValueError("An instruction needs some text.")
    instruction = Instruction.objects.create(text=text, user=user, source=source, answer_to=answer_to)
    audit.record(user, "instruct", text[:255], instruction=instruction.pk, source=source)
    if answer_to is not None:
        close_dialog(answer_to, "answered")
    result = parse if parse is not None else _interpret(text)
    instruction.parse = result
    instruction.type = result.get("type", "")
    instruction.interpreted_at = timezone.now()
    instruction.save(update_fields=["parse", "type", "interpreted_at"])
    if result.get("needs_user") or not result.get("valid", True):
        return _ask(instruction, result)
    if any(step.get("action") == "stop" for step in result.get("steps", [])):
        return _stop(instruction, result, user)
    try:
        per_robot = dispatch.plan(result, user, check_schedule=source != "schedule")
        dispatch.dispatch(instruction, per_robot)
    except (dispatch.Refused, ControlRefused) as exc:
        return _close(instruction, Instruction.Status.REFUSED, str(exc))
    live.instruction(instruction)
    return instruction


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


def close_dialog(instruction: Instruction, reason: str) -> None:
    """Bring the robots waiting on this instruction's question back to ready."""
    for robot in Robot.objects.filter(
        transitions__instruction=instruction, state=Robot.State.DIALOG
    ).distinct():
        Robot.objects.transition(robot.pk, Event.DONE, reason, instruction)
    if instruction.status == Instruction.Status.NEEDS_USER:
        _close(instruction, Instruction.Status.CANCELLED, f"{instruction.outcome} ({reason})")


def _stop(instruction: Instruction, result: dict, user) -> Instruction:
    from execution.control import stop

    names = set()
    for step in result.get("steps", []):
        robots = step.get("robots")
        if not isinstance(robots, list) or not robots:  # "stop", "stop all": every robot
            names |= set(Robot.objects.values_list("name", flat=True))
        else:
            names |= set(robots)
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
