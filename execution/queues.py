"""Each robot's queue, as the task list shows it: what runs now (its step "2 of 3", the distance left to a move's
goal and an ETA) and what waits behind it, in the order the runner takes them (Execution.queued_at); a waiting
instruction moved one place up or down is a swap of two places in that order. Pushed to the pages (live.queue)
whenever an instruction of the robot changes; the API reads the same (GET /api/robots/{name}/queue).
"""

from __future__ import annotations

import math
from datetime import timedelta

from django.db.models import Case, IntegerField, Value, When

import live
from access.leases import check_cancel
from audit import records as audit
from execution.models import Execution, ExecutionQuerySet
from fleetcore.speed import Limits, pace
from interpreter.forms import read_back
from robots import poses as pose_store
from robots.models import Robot

WAITING = ExecutionQuerySet.WAITING
ACTIVE = (Execution.Status.RUNNING, *WAITING)


class NotQueued(ValueError):
    """The instruction does not wait in that robot's queue; the message says so."""


def running_first():
    """An ordering that puts the running execution before the waiting ones."""
    return Case(
        When(status=Execution.Status.RUNNING, then=Value(0)), default=Value(1), output_field=IntegerField()
    )


def robot_queue(robot: Robot) -> dict:
    """What the robot runs now (its step "2 of 3", the distance left to a move's goal from its last pose, an
    ETA at the step's speed) and what waits behind it, in queue order: the API's and the page's task list."""
    return robot_queues([robot])[0]


def robot_queues(robots) -> list[dict]:
    """robot_queue of each of these robots, read at once: one query and one read of the last poses for all
    (an instruction to 50 robots pushed 50 task lists at three round trips each: most of its POST's 2 s)."""
    robots = list(robots)
    rows: dict[int, list[Execution]] = {robot.pk: [] for robot in robots}
    for row in (
        Execution.objects.filter(robot_id__in=list(rows), status__in=ACTIVE)
        .select_related("instruction__user")
        .order_by(running_first(), "queued_at", "pk")
    ):
        rows[row.robot_id].append(row)
    running = {
        pk: next((row for row in own if row.status == Execution.Status.RUNNING), None)
        for pk, own in rows.items()
    }
    poses = (
        pose_store.last_poses([pk for pk, row in running.items() if row is not None])
        if any(running.values())
        else {}
    )
    out = []
    for robot in robots:
        now = running[robot.pk]
        waiting = [row for row in rows[robot.pk] if row is not now]
        out.append(
            {
                "robot": robot.name,
                "id": robot.pk,
                "running": _entry(now, robot, poses.get(robot.pk)) if now else None,
                "queued": [
                    _entry(row, robot, None, position) for position, row in enumerate(waiting, start=1)
                ],
            }
        )
    return out


def _entry(row: Execution, robot: Robot, pose: dict | None, position: int = 0) -> dict:
    steps = row.steps or []
    index = min(row.step_index, len(steps) - 1) if steps else 0
    step = steps[index] if steps else {}
    entry = {
        "instruction": row.instruction_id,
        "text": row.instruction.text,
        "user": getattr(row.instruction.user, "username", None),
        "status": row.status,
        "position": position,
        "step": index + 1 if steps else None,
        "steps": len(steps),
        "doing": read_back(step) if step else "",
        "goal": _goal(step),
        "distance_left": None,
        "speed": None,
        "eta_s": None,
    }
    if pose is not None:
        entry.update(progress(step, pose, robot.max_linear, robot.max_angular))
    return entry


def _goal(step: dict) -> dict | None:
    """A move's goal on the map ({name, x, y}), for the page to age the distance left with each pose."""
    goal = step.get("destination") if isinstance(step, dict) else None
    if not goal or goal.get("x") is None or goal.get("y") is None:
        return None
    return {"name": goal.get("name") or "", "x": float(goal["x"]), "y": float(goal["y"])}


def progress(step: dict, pose: dict, max_linear: float, max_angular: float) -> dict:
    """A move's distance left (straight line from the pose to its goal, m), the step's speed (its pace for the
    robot's limits, fleetcore.speed, m/s) and so an ETA (s); {} for a step with no goal on the map."""
    goal = _goal(step)
    if goal is None:
        return {}
    left = math.dist((pose["x"], pose["y"]), (goal["x"], goal["y"]))
    try:
        speed = pace(step.get("speed"), Limits(max_linear, max_angular)).limits.linear
    except ValueError:  # a word nobody defined (UnknownSpeed), or a robot with no limits yet
        speed = 0.0
    eta = left / speed if speed > 0 else None
    return {
        "distance_left": round(left, 2),
        "speed": round(speed, 3),
        "eta_s": round(eta, 1) if eta else None,
    }


def move_in_queue(instruction, robot: Robot, user, up: bool) -> list[int]:
    """Move a waiting instruction one place up or down the robot's queue (it swaps places with its neighbour:
    their queued_at, the one order the runner reads); the queue's instruction ids after. The same rules as a
    cancel (it changes when someone's work runs: access.leases.check_cancel); NotQueued when it does not wait there."""
    pk = getattr(instruction, "pk", instruction)
    rows = list(
        Execution.objects.filter(robot=robot, status__in=WAITING)
        .select_related("instruction__user")
        .order_by("queued_at", "pk")
    )
    at = next((i for i, row in enumerate(rows) if row.instruction_id == pk), None)
    if at is None:
        raise NotQueued(f"Instruction #{pk} does not wait in {robot.name}'s queue.")
    if user is not None:
        check_cancel(user, rows[at].instruction.user, [robot])
    other = at - 1 if up else at + 1
    if 0 <= other < len(rows):
        _swap(rows[at], rows[other])
        rows[at], rows[other] = rows[other], rows[at]
        audit.record(user, "queue.move", f"#{pk}", robot=robot.name, up=up, position=other + 1)
        live.queue(robot_queue(robot))
    return [row.instruction_id for row in rows]


def _swap(a: Execution, b: Execution) -> None:
    """Swap two executions' places (equal stamps are told apart by a microsecond: the order must change)."""
    first, second = sorted((a.queued_at, b.queued_at))
    if first == second:
        second = first + timedelta(microseconds=1)
    earlier, later = (a, b) if (a.queued_at, a.pk) < (b.queued_at, b.pk) else (b, a)
    Execution.objects.filter(pk=earlier.pk).update(queued_at=second)
    Execution.objects.filter(pk=later.pk).update(queued_at=first)


def all_queues() -> list[dict]:
    """Every robot's queue that has something in it (the dashboard's first state)."""
    busy = Execution.objects.filter(status__in=ACTIVE).values_list("robot_id", flat=True).distinct()
    return robot_queues(Robot.objects.filter(pk__in=list(busy)).order_by("name"))


def push_queues(robot_ids) -> None:
    """Push the queues of these robots to the pages (after the commit): their task lists changed."""
    push_robot_queues(Robot.objects.filter(pk__in=list(robot_ids)))


def push_robot_queues(robots) -> None:
    """push_queues of robots already read (a claim has its robot): one query for all their lists."""
    for queue in robot_queues(robots):
        live.queue(queue)
