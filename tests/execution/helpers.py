"""Hand-made interpreter results and waiting helpers for execution tests."""

import dataclasses
import math
import time

from execution.models import Instruction
from robots.models import StateTransition


def step(robots, x=None, y=None, name="P", task=None, speed="very fast", action="move"):
    """One interpreter step (the contract of interpreter.service.interpret)."""
    destination = {"name": name, "x": x, "y": y} if x is not None else None
    return {"action": action, "robots": robots, "destination": destination, "task": task, "speed": speed}


def parse(*steps):
    return {
        "type": "I",
        "valid": True,
        "needs_user": False,
        "question": None,
        "steps": list(steps),
        "reason": "",
    }


def wait_final(instruction: Instruction, timeout: float = 40.0) -> Instruction:
    """Poll until the instruction is final (the timeout only guards against a hang; it asserts nothing)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        instruction.refresh_from_db()
        if instruction.is_final:
            return instruction
        time.sleep(0.05)
    raise AssertionError(f"instruction #{instruction.pk} still {instruction.status}: {instruction.outcome}")


def wait_for(predicate, timeout: float = 20.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def transitions(robot_name: str) -> list[tuple[str, str, str, int | None]]:
    rows = StateTransition.objects.filter(robot__name=robot_name).order_by("at", "pk")
    return list(rows.values_list("from_state", "to_state", "reason", "instruction_id"))


def without_command_timeout(sim, name: str) -> None:
    """Make a simulated robot keep its last velocity command for ever, like a base without cmd_vel timeout."""
    body = sim.fleet.robots[name].body
    sim.call(lambda: setattr(body, "profile", dataclasses.replace(body.profile, cmd_timeout=math.inf)))


def at_rest(sim, name: str) -> bool:
    """The simulated body has stopped, on a zero command (not only by its command timeout)."""
    body = sim.fleet.robots[name].body
    return sim.call(lambda: body.vx == 0.0 and body.wz == 0.0 and (body.cmd.vx, body.cmd.wz) == (0.0, 0.0))


def wait_each(sim, sent: dict, timeout: float) -> tuple[dict, dict]:
    """Each instruction once final, and where the simulator had its robot when it was (a robot that ended at
    its free spot may later be asked to make way by one still coming, and stand back a few centimetres off:
    a later instruction's doing, in the history under its own words)."""
    done, said_at, deadline = {}, {}, time.monotonic() + timeout
    while len(done) < len(sent) and time.monotonic() < deadline:
        for name, instruction in sent.items():
            if name not in done:
                instruction.refresh_from_db()
                if instruction.is_final:
                    done[name], said_at[name] = instruction, sim.pose(name)
        time.sleep(0.05)
    assert len(done) == len(sent), {
        name: (i.status, i.outcome) for name, i in sent.items() if name not in done
    }
    return done, said_at
