"""From an interpreted instruction to per-robot executions: who, where, in which order, or why not.

Rules (the paper's Figure 6 and section 3.8):
- A robot inside one of its scheduled time slots is refused to people, with the slot named and the time it
  is free again (the schedule comes first); "all robots" means the robots online and free now.
- The user must be allowed to command every robot (access.leases), else the whole instruction is refused.
- Several robots sent to one destination get goals on a ring around it, in the order of their bearings,
  so their paths do not cross and they do not meet at the goal.
- A new instruction preempts a robot's activity of lower priority (work > motion > dialog > ready); else it
  queues behind it.
"""

from __future__ import annotations

import math
import threading
from collections import defaultdict

from django.conf import settings
from django.db import connections, transaction
from django.utils import timezone

from access import leases
from access.leases import ControlRefused, check_command
from execution import coordination
from execution.models import Execution, Instruction, TimeSlot
from fleetcore import states as statemachine
from fleetcore import steps as step_contract
from fleetcore.states import Admission, Event
from fleetcore.steps import ANY, Step
from robots import poses as pose_store
from robots.models import Robot

FINAL = ("succeeded", "failed", "cancelled")
RING_MARGIN = 0.35  # metres between neighbouring robots on the ring


class Refused(Exception):
    """The instruction cannot run; the message says why, in words for a person."""


def local_time(moment=None):
    """The local wall-clock time of a moment (schedules are in local time)."""
    return timezone.localtime(moment or timezone.now()).time()


def active_slot(robot: Robot, moment=None) -> TimeSlot | None:
    """The robot's enabled time slot covering this moment, if any."""
    now = local_time(moment)
    return TimeSlot.objects.running_at(now).filter(robot=robot).select_related("goal").first()


def describe_slot(slot: TimeSlot) -> str:
    task = f" + {slot.task}" if slot.task else ""
    return f"{slot.start:%H:%M}-{slot.end:%H:%M} ({slot.goal.name}{task})"


def free_robots(moment=None) -> list[Robot]:
    """Robots online and not inside a scheduled slot now."""
    robots = Robot.objects.filter(link_status=Robot.Link.ONLINE)
    return [robot for robot in robots if active_slot(robot, moment) is None]


def resolve_robots(step: dict, moment=None, check_schedule: bool = True, user=None) -> list[Robot]:
    """The robots a step names, each online and (for people) outside its scheduled slots."""
    names = step.get("robots")
    if names in (None, "", ANY):
        return [allocate(Step.from_dict(step), user, moment, check_schedule)]
    if names == "all":
        robots = free_robots(moment) if check_schedule else list(Robot.objects.filter(link_status="online"))
        if not robots:
            raise Refused("No robot is free now (all are offline or busy with their schedules).")
        return robots
    if not names:
        raise Refused("Say which robot should do it (a name, or 'all robots').")
    found = {robot.name: robot for robot in Robot.objects.filter(name__in=names)}
    missing = [name for name in names if name not in found]
    if missing:
        raise Refused(f"No robot named {', '.join(missing)} is registered.")
    robots = [found[name] for name in names]
    for robot in robots:
        if robot.link_status != Robot.Link.ONLINE:
            raise Refused(f"{robot.name} is {robot.link_status}; it cannot take instructions now.")
        slot = active_slot(robot, moment) if check_schedule else None
        if slot is not None:
            raise Refused(
                f"{robot.name} is busy with its schedule {describe_slot(slot)}; it is free from {slot.end:%H:%M}."
            )
    return robots


def allocate(step: Step, user=None, moment=None, check_schedule: bool = True) -> Robot:
    """The one best robot for a step that names none: capable, free, nearest to the destination.

    Capable: bound for what the action needs (fleetcore/actions.py). Free: online and ready, no running or queued
    instruction, no schedule slot now, no lease held by someone else. Nearest: straight-line distance from its
    last pose to the destination (robots without a known pose come last). Ties: the lower name.
    Refused, naming why each robot was passed over, when none is free.
    """
    candidates = list(Robot.objects.filter(link_status=Robot.Link.ONLINE).prefetch_related("bindings"))
    busy = set(
        Execution.objects.filter(robot__in=candidates)
        .exclude(status__in=FINAL)
        .values_list("robot_id", flat=True)
    )
    held = {lease.robot_id: lease.user for lease in leases.active([r.pk for r in candidates])}
    passed_over, free = [], []
    for robot in candidates:
        roles = {b.action for b in robot.bindings.all() if b.target}
        why = _unfit(robot, step, roles, robot.pk in busy, held.get(robot.pk), user, moment, check_schedule)
        (passed_over.append(f"{robot.name} {why}") if why else free.append(robot))
    if not free:
        detail = "; ".join(passed_over) or "no robot is online"
        raise Refused(
            f"No robot is free to {step.action} now ({detail}). Name one, or try again when one is free."
        )
    poses = pose_store.last_poses([robot.pk for robot in free])
    target = (step.destination.x, step.destination.y) if step.destination else None

    def distance(robot: Robot) -> float:
        pose = poses.get(robot.pk) or _start(robot)
        return math.dist((pose["x"], pose["y"]), target) if pose and target else math.inf

    return min(free, key=lambda robot: (distance(robot), robot.name))


def _unfit(robot, step: Step, roles, busy, holder, user, moment, check_schedule) -> str | None:
    """Why this robot cannot take the step now, in words; None when it can."""
    missing = step.spec.missing(roles)
    if missing:
        return f"has no {' and no '.join(missing)} bound"
    if busy or robot.state != Robot.State.READY:
        return f"is busy ({robot.state})"
    if holder is not None and holder != user:
        return f"is held by {holder.username}"
    if check_schedule and (slot := active_slot(robot, moment)) is not None:
        return f"has its schedule {describe_slot(slot)}"
    return None


def _start(robot: Robot) -> dict | None:
    pose = robot.start_pose
    return {"x": pose[0], "y": pose[1]} if pose and len(pose) >= 2 else None


def radius_of(robot: Robot) -> float:
    """Half the largest extent of the robot's footprint (0.3 m when unknown)."""
    points = robot.footprint or []
    if not points:
        return 0.3
    return max(math.hypot(x, y) for x, y in points)


def ring_goals(destination: dict, robots: list[Robot], poses: dict) -> dict[int, dict]:
    """A goal per robot on a ring around the destination, in the cyclic order of the robots' bearings.

    The ring's rotation is the circular mean of (bearing - slot angle), so each robot's slot lies on its own
    side of the destination and the paths of neighbours do not cross.
    """
    cx, cy = float(destination["x"]), float(destination["y"])
    n = len(robots)
    spacing = 2 * max(radius_of(robot) for robot in robots) + RING_MARGIN
    radius = max(spacing / (2 * math.sin(math.pi / n)), spacing) if n > 1 else 0.0

    def bearing(robot):
        x, y, _ = poses.get(robot.pk) or (robot.start_pose or (cx - 1.0, cy, 0.0))
        return math.atan2(y - cy, x - cx)

    ordered = sorted(robots, key=bearing)
    offsets = [bearing(robot) - 2 * math.pi * i / n for i, robot in enumerate(ordered)]
    rotation = math.atan2(sum(map(math.sin, offsets)), sum(map(math.cos, offsets)))
    goals = {}
    for i, robot in enumerate(ordered):
        angle = rotation + 2 * math.pi * i / n
        goals[robot.pk] = {
            **destination,
            "x": round(cx + radius * math.cos(angle), 3),
            "y": round(cy + radius * math.sin(angle), 3),
            "around": destination.get("name"),
        }
    return goals


def plan(parse: dict, user, moment=None, check_schedule: bool = True) -> dict[Robot, list[dict]]:
    """Split the interpreter's steps into each robot's list of steps, or raise Refused."""
    per_robot: dict[int, list[dict]] = defaultdict(list)
    robots_by_id: dict[int, Robot] = {}
    try:
        steps = step_contract.validate(parse.get("steps"))
    except step_contract.StepError as exc:
        raise Refused(str(exc)) from None
    poses = {
        pk: (p["x"], p["y"], p.get("yaw", 0.0))
        for pk, p in pose_store.last_poses(Robot.objects.values_list("pk", flat=True)).items()
    }
    for checked, step in zip(steps, parse["steps"], strict=True):
        step = checked.to_dict()
        robots = resolve_robots(step, moment, check_schedule, user)
        destination = step.get("destination")
        goals = ring_goals(destination, robots, poses) if destination and len(robots) > 1 else {}
        for robot in robots:
            robots_by_id[robot.pk] = robot
            per_robot[robot.pk].append(
                {**step, "robots": [robot.name], "destination": goals.get(robot.pk, destination)}
            )
    if not per_robot:
        raise Refused("The instruction has no step a robot can do.")
    if user is not None:
        for robot in robots_by_id.values():
            try:
                check_command(user, robot)
            except ControlRefused as exc:
                raise Refused(str(exc)) from None
    return {robots_by_id[pk]: steps for pk, steps in per_robot.items()}


@transaction.atomic
def dispatch(instruction: Instruction, per_robot: dict[Robot, list[dict]]) -> list[Execution]:
    """Create the executions, wake or preempt robots as the state machine says, and queue the instruction."""
    now = timezone.now()
    executions, preempts = [], []
    for robot, steps in per_robot.items():
        robot.refresh_from_db(fields=["state", "link_status"])
        if robot.state in (Robot.State.OFFLINE, Robot.State.REGISTERED):
            Robot.objects.transition(robot.pk, Event.LINK_UP, "woken by an instruction", instruction)
            robot.refresh_from_db(fields=["state"])
        priority = step_contract.priority(steps)
        admission = statemachine.admit(robot.state, priority)
        execution = Execution.objects.create(
            instruction=instruction, robot=robot, steps=steps, priority=priority, dispatched_at=now
        )
        executions.append(execution)
        if admission == Admission.PREEMPT:
            preempts.append((robot.pk, execution.pk))
    instruction.robots.set([robot.pk for robot in per_robot])
    Instruction.objects.filter(pk=instruction.pk).update(status=Instruction.Status.QUEUED, dispatched_at=now)
    instruction.status, instruction.dispatched_at = Instruction.Status.QUEUED, now
    transaction.on_commit(lambda: _after_commit(instruction.pk, preempts))
    return executions


def _after_commit(instruction_id: int, preempts: list[tuple[int, int]]) -> None:
    for robot_id, execution_id in preempts:
        coordination.request_preempt(robot_id, execution_id)
    launch("execute_instruction", instruction_id)


def launch(task: str, pk: int) -> None:
    """Start a fleet task: on the Celery workers (FLEET_EXECUTE=celery, the default) or in a thread here."""
    from execution import tasks

    if getattr(settings, "FLEET_EXECUTE", "celery") == "thread":
        threading.Thread(target=_in_thread, args=(getattr(tasks, task), pk), daemon=True).start()
        return
    queue = getattr(settings, "FLEET_EXECUTE_QUEUE", "") or None
    getattr(tasks, task).apply_async((pk,), queue=queue)


def _in_thread(task, pk: int) -> None:
    try:
        task.run(pk)
    finally:
        connections.close_all()
