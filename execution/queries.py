"""Questions answered from live state, moving nothing: where a robot is, what it is doing, which robots are free,
how far one is from a place, what one can do.

A question is an instruction whose steps are all query actions (fleetcore/actions.py, category "query";
`Interpretation.is_question`); submit
answers it at once in the instruction's outcome (the console and the API show it like any other outcome): no
execution is queued, so a busy robot is answered about without waiting for it.
"""

from __future__ import annotations

import math

from execution import dispatch, route
from execution.models import Execution
from fleetcore import geometry
from fleetcore.actions import ACTIONS
from fleetcore.choice import NAMES, RobotChoice
from fleetcore.interpretation import Interpretation
from places.models import Location
from robots import poses as pose_store
from robots.models import Robot

ACTIVE = (Execution.Status.RUNNING, Execution.Status.QUEUED, Execution.Status.PREEMPTED)


def answer(understood: Interpretation, selected: list[int] | None = None) -> tuple[str, list[Robot]]:
    """The answer to each question step (Interpretation.is_question), in words, and the robots it is about."""
    lines, about = [], {}
    for step, chosen in zip(understood.steps, understood.choices, strict=True):
        robots = _robots(chosen, selected)
        about.update({robot.pk: robot for robot in robots})
        lines.append(_ANSWERS[step["action"]](step, robots))
    return " ".join(lines), list(about.values())


def _robots(chosen: RobotChoice | None, selected: list[int] | None) -> list[Robot]:
    """The robots a question names; unnamed: the ones selected on the page, else every robot (of its kind)."""
    if chosen is not None and chosen.mode == NAMES:
        found = {robot.name: robot for robot in Robot.objects.filter(name__in=chosen.names)}
        missing = [name for name in chosen.names if name not in found]
        if missing:
            raise dispatch.Refused(f"No robot named {', '.join(missing)} is registered.")
        return [found[name] for name in chosen.names]
    rows = Robot.objects.filter(pk__in=selected) if selected else Robot.objects.all()
    return [robot for robot in rows.order_by("name") if dispatch.matches(robot, chosen)]


def _where(step: dict, robots: list[Robot]) -> str:
    poses = pose_store.last_poses([robot.pk for robot in robots])
    faults = pose_store.pose_faults([robot.pk for robot in robots])
    places = list(Location.objects.values_list("name", "x", "y"))
    return (
        " ".join(
            _position_words(robot, poses.get(robot.pk), faults.get(robot.pk), places) for robot in robots
        )
        or "No robot."
    )


def _position_words(robot: Robot, pose: dict | None, fault: dict | None, places) -> str:
    if fault is not None:
        last = f"; its last good position was ({pose['x']:.2f}, {pose['y']:.2f})" if pose else ""
        return f"{pose_store.fault_words(robot.name, fault)}{last}."
    if pose is None:
        return f"{robot.name}: position not known yet ({robot.link_status})."
    x, y = float(pose["x"]), float(pose["y"])
    heading = math.degrees(geometry.wrap(float(pose.get("yaw", 0.0))))
    near = min(places, key=lambda p: math.dist((x, y), (p[1], p[2])), default=None)
    at = f", {math.dist((x, y), (near[1], near[2])):.1f} m from {near[0]}" if near else ""
    return f"{robot.name} {_is_at(pose)} ({x:.2f}, {y:.2f}), heading {heading:.0f}°{at}."


def _is_at(pose: dict) -> str:
    """ "is at", or for a stale pose "was at, 3.2 s ago (stale)," said before the place."""
    age = pose_store.pose_age(pose)
    if age is None or age <= pose_store.STALE_S:
        return "is at"
    return f"was, {age:.1f} s ago (stale), at"


def _doing(step: dict, robots: list[Robot]) -> str:
    rows = Execution.objects.filter(robot__in=robots, status__in=ACTIVE).select_related("instruction")
    work: dict[int, list[Execution]] = {}
    for row in rows.order_by("queued_at", "pk"):
        work.setdefault(row.robot_id, []).append(row)
    return " ".join(_doing_words(robot, work.get(robot.pk, [])) for robot in robots) or "No robot."


def _doing_words(robot: Robot, rows: list[Execution]) -> str:
    running = next((row for row in rows if row.status == Execution.Status.RUNNING), None)
    queued = len(rows) - (running is not None)
    if running is None:
        what = "nothing" if robot.state in dispatch.IDLE else robot.state
        text = f"{robot.name} is doing {what} ({robot.state}, link {robot.link_status})"
    else:
        step = running.steps[min(running.step_index, len(running.steps) - 1)] if running.steps else {}
        text = (
            f"{robot.name} is in {robot.state}: instruction #{running.instruction_id} "
            f"'{running.instruction.text}', step {running.step_index + 1} of {len(running.steps)} "
            f"({_step_words(step)})"
        )
    return text + (f", {queued} more queued." if queued else ".")


def _step_words(step: dict) -> str:
    where = (step.get("destination") or {}).get("name")
    amount = f" {step['amount']:g}" if step.get("amount") is not None else ""
    return f"{step.get('action', '?')}{amount}" + (f" to {where}" if where else "")


def _free(step: dict, robots: list[Robot]) -> str:
    """Free as allocation means it: online, idle, nothing running or queued, no schedule slot now."""
    busy = set(
        Execution.objects.filter(robot__in=robots)
        .exclude(status__in=dispatch.FINAL)
        .values_list("robot_id", flat=True)
    )
    slots = dispatch.slots_now(robots)
    free, other = [], []
    for robot in robots:
        if robot.link_status != Robot.Link.ONLINE:
            other.append(f"{robot.name} is {robot.link_status}")
        elif robot.pk in busy or robot.state not in dispatch.IDLE:
            other.append(f"{robot.name} is busy ({robot.state})")
        elif robot.pk in slots:
            other.append(f"{robot.name} has its schedule {dispatch.describe_slot(slots[robot.pk])}")
        else:
            free.append(robot.name)
    head = f"Free: {', '.join(free)}." if free else "No robot is free now."
    return head + (f" Not free: {'; '.join(other)}." if other else "")


def _distance(step: dict, robots: list[Robot]) -> str:
    target = step["destination"]
    goal = (float(target["x"]), float(target["y"]))
    poses = pose_store.last_poses([robot.pk for robot in robots])
    faults = pose_store.pose_faults([robot.pk for robot in robots])
    row = route.fleet_map()
    lines = []
    for robot in robots:
        pose = poses.get(robot.pk)
        if robot.pk in faults:
            words = pose_store.fault_words(robot.name, faults[robot.pk])
            lines.append(f"{words}; I cannot say how far it is from {target['name']}.")
            continue
        if pose is None:
            lines.append(f"{robot.name}: position not known yet.")
            continue
        start = (float(pose["x"]), float(pose["y"]))
        planned = route.planned_length(robot, start, goal, row)
        path = f"{planned:.1f} m along its path" if planned is not None else "no path fits it"
        age = pose_store.pose_age(pose)
        stale = f" (by its last pose, {age:.1f} s old: stale)" if age and age > pose_store.STALE_S else ""
        lines.append(
            f"{robot.name} is {math.dist(start, goal):.1f} m from {target['name']} in a straight line "
            f"({path}){stale}."
        )
    return " ".join(lines) or "No robot."


def _abilities(step: dict, robots: list[Robot]) -> str:
    lines = []
    for robot in Robot.objects.filter(pk__in=[r.pk for r in robots]).prefetch_related("bindings"):
        roles = {b.action for b in robot.bindings.all() if b.target}
        can, cannot = [], []
        for spec in ACTIONS.values():
            if spec.category in ("query", "control") and spec.name not in ("dock", "wait"):
                continue
            missing = spec.missing(roles)
            (
                cannot.append(f"{spec.name} (no {' and no '.join(missing)} bound)")
                if missing
                else can.append(spec.name)
            )
        line = f"{robot.name} can {', '.join(can) or 'nothing yet'}"
        lines.append(line + (f"; not {', '.join(cannot)}." if cannot else "."))
    return " ".join(lines) or "No robot."


_ANSWERS = {
    "report_position": _where,
    "report_status": _doing,
    "list_free": _free,
    "report_distance": _distance,
    "list_abilities": _abilities,
}
