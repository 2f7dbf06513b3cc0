"""From an interpreted instruction to per-robot executions: who, where, in which order, or why not.

Rules (the paper's Figure 6 and section 3.8):
- A robot inside one of its scheduled time slots is refused to people, with the slot named and the time it
  is free again (the schedule comes first); "all robots" means the robots online and free now.
- The user must be allowed to command every robot (access.leases), else the whole instruction is refused.
- An instruction that names no robot goes to the robots selected on the page, else to the one best robot
  (`allocate`: capable, free, shortest planned path); when none is free it waits for one (`wait`, `retry`).
- Goals are spots nobody else takes (execution/spots.py): several robots sent to one place get spots on a ring
  in the order of their bearings; a place taken by a parked robot or another's goal gives the nearest free spot
  the robot can get to that walls off no goal given before it.
- A new instruction preempts a robot's activity of lower priority (work > motion > dialog > ready); else it
  queues behind it.
- A robot a person stopped is held (access.holds): "any" and "all robots" leave it out (and say so), the
  system's instructions (schedule, traffic) are refused it, a person's instruction naming it releases it.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field, replace

from django.db import transaction
from django.utils import timezone

import live
from access import holds, leases
from access.leases import ControlRefused, check_command
from execution import coordination, executor, route, spots
from execution.models import Execution, Instruction, TimeSlot
from fleetcore import states as statemachine
from fleetcore import steps as step_contract
from fleetcore.choice import ALL, RobotChoice
from fleetcore.interpretation import Interpretation
from fleetcore.states import Admission, Event
from fleetcore.steps import Step
from interpreter.forms import read_back
from robots import poses as pose_store
from robots.models import Robot

FINAL = ("succeeded", "failed", "cancelled")
TIE_M = 0.05  # planned paths this close in length are a tie (then battery, then name)
IDLE = (Robot.State.READY, Robot.State.REGISTERED, Robot.State.OFFLINE)  # dispatch wakes the last two
MAX_REASONS = 6  # robots passed over named in an answer; the rest are counted


class Refused(Exception):
    """The instruction cannot run; the message says why, in words for a person."""


class NoneFree(Refused):
    """Robots that could do it exist, but none is free now: the instruction may wait for one."""


def local_time(moment=None):
    """The local wall-clock time of a moment (schedules are in local time)."""
    return timezone.localtime(moment or timezone.now()).time()


def describe_slot(slot: TimeSlot) -> str:
    task = f" + {slot.task}" if slot.task else ""
    return f"{slot.start:%H:%M}-{slot.end:%H:%M} ({slot.goal.name}{task})"


def slots_now(robots, moment=None) -> dict[int, TimeSlot]:
    """Per robot id: its enabled time slot covering this moment (one query for many robots)."""
    now = local_time(moment)
    slots = TimeSlot.objects.filter(robot__in=robots, enabled=True, start__lte=now, end__gt=now)
    return {slot.robot_id: slot for slot in slots.select_related("goal")}


def free_robots(moment=None) -> list[Robot]:
    """Robots online and not inside a scheduled slot now."""
    robots = list(Robot.objects.filter(link_status=Robot.Link.ONLINE))
    slots = slots_now(robots, moment)
    return [robot for robot in robots if robot.pk not in slots]


def resolve_robots(
    step: Step, moment=None, check_schedule: bool = True, user=None
) -> tuple[list[Robot], str]:
    """The robots a step names, each online and (for people) outside its scheduled slots; and, for a step
    that names none, why the one chosen was chosen."""
    chosen = step.robots
    if chosen.unnamed:
        robot, why = allocate(step, user, moment, check_schedule)
        return [robot], why
    if chosen.mode == ALL:
        robots = free_robots(moment) if check_schedule else list(Robot.objects.filter(link_status="online"))
        robots = [robot for robot in robots if matches(robot, chosen)]
        if not robots:
            raise Refused(
                f"No robot{_of(chosen)} is free now (all are offline or busy with their schedules)."
            )
        return robots, ""
    names = chosen.names
    found = {robot.name: robot for robot in Robot.objects.filter(name__in=names).prefetch_related("bindings")}
    missing = [name for name in names if name not in found]
    if missing:
        raise Refused(f"No robot named {', '.join(missing)} is registered.")
    robots = [found[name] for name in names]
    slots = slots_now(robots, moment) if check_schedule else {}  # one query for all of them
    for robot in robots:
        if robot.link_status != Robot.Link.ONLINE:
            raise Refused(f"{robot.name} is {robot.link_status}; it cannot take instructions now.")
        if unbound := _unbound(robot, step):
            raise Refused(
                f"{robot.name} cannot {step.action}: it {unbound}; choose one on its registration page."
            )
        slot = slots.get(robot.pk)
        if slot is not None:
            raise Refused(
                f"{robot.name} is busy with its schedule {describe_slot(slot)}; it is free from {slot.end:%H:%M}."
            )
    return robots, ""


def matches(robot: Robot, chosen: RobotChoice | None) -> bool:
    """Whether the robot is one of those chosen (by name, kind or exclusion); any robot for None."""
    return chosen is None or chosen.means(robot.name, robot.model, robot.drive)


def _of(chosen: RobotChoice) -> str:
    """ " (turtlebot, not husky)": the choice's filter in words, for an answer."""
    words = ([chosen.kind] if chosen.kind else []) + [f"not {name}" for name in chosen.exclude]
    return f" ({', '.join(words)})" if words else ""


def allocate(step: Step, user=None, moment=None, check_schedule: bool = True) -> tuple[Robot, str]:
    """The one best robot for a step that names none, and why it, in words for a person.

    Capable: bound for what the action needs (fleetcore/actions.py) and able to reach the destination (a planned
    path fits its footprint). Free: online and ready, no running or queued instruction, no schedule slot now, no
    lease held by someone else. Best: the shortest planned path from its last pose (route.planned_length, the
    planner route.py drives with); ties by battery when known, then the name. NoneFree (the instruction may
    wait) when capable robots exist but none is free; Refused when no robot could ever do it.
    """
    chosen = step.robots
    online = Robot.objects.filter(link_status=Robot.Link.ONLINE).select_related("held_by")
    candidates = [robot for robot in online.prefetch_related("bindings") if matches(robot, chosen)]
    busy = set(
        Execution.objects.filter(robot__in=candidates)
        .exclude(status__in=FINAL)
        .values_list("robot_id", flat=True)
    )
    held = {lease.robot_id: lease.user for lease in leases.active([r.pk for r in candidates])}
    slots = slots_now(candidates, moment) if check_schedule else {}
    incapable, not_now, free = [], [], []
    for robot in candidates:
        if unbound := _unbound(robot, step):
            incapable.append(f"{robot.name} {unbound}")
            continue
        why = _not_free(robot, robot.pk in busy, held.get(robot.pk), user, slots.get(robot.pk))
        (not_now.append(f"{robot.name} {why}") if why else free.append(robot))
    if not free:
        detail = _listed(not_now + incapable) or "no robot is online"
        if not_now:
            raise NoneFree(f"No robot{_of(chosen)} is free to {step.action} now ({detail}).")
        raise Refused(f"No robot{_of(chosen)} can {step.action} ({detail}).")
    robot, why, unreachable = best_of(free, step.destination)
    return robot, chosen_words([robot.name], why, unreachable + not_now + incapable)


def _unbound(robot: Robot, step: Step) -> str:
    """ "has no camera bound": what the robot lacks for the step's action (fleetcore/actions.py needs), in
    words; "" when its bindings serve it."""
    missing = step.spec.missing({b.action for b in robot.bindings.all() if b.target})
    return f"has no {' and no '.join(missing)} bound" if missing else ""


def chosen_words(names: list[str], why: str, passed: list[str] = ()) -> str:
    """Whom the portal chose for an instruction that names no robot, and why, in the one form every answer
    gives: "husky chosen (no robot named): the nearest free robot, 4.0 m to A (tiago 5.4+ m); spot is busy"."""
    passed_over = f"; {_listed(list(passed))}" if passed else ""
    return f"{', '.join(names)} chosen (no robot named): {why}{passed_over}"


def _not_free(robot, busy: bool, holder, user, slot: TimeSlot | None) -> str | None:
    """Why this capable robot cannot take the step now, in words; None when it can."""
    if busy or robot.state not in IDLE:
        return f"is busy ({robot.state})"
    if robot.held_at is not None:
        return f"is {robot.hold_words}"
    if holder is not None and holder != user:
        return f"is held by {holder.username}"
    if slot is not None:
        return f"has its schedule {describe_slot(slot)}"
    return None


def _listed(reasons: list[str]) -> str:
    shown = ", ".join(reasons[:MAX_REASONS])
    return shown + (f" and {len(reasons) - MAX_REASONS} more" if len(reasons) > MAX_REASONS else "")


def best_of(free: list[Robot], destination) -> tuple[Robot, str, list[str]]:
    """The free robot with the shortest planned path to the destination (branch and bound: the straight line
    is a lower bound of any path, so robots farther in a straight line than the best path are not planned).

    Returns the robot, why it in words, and the robots that cannot reach the destination (in words).
    Without a destination: the fullest battery when known, then the name.
    """
    poses = pose_store.known_poses(free)
    if destination is None:
        robot = min(free, key=lambda r: (-(_battery(r, poses) or 0.0), r.name))
        return robot, _no_place_words(robot, free, poses), []
    target = (destination.x, destination.y)
    starts = {robot.pk: _position(robot, poses) for robot in free}
    ranked = sorted(
        free, key=lambda r: (math.dist(starts[r.pk], target) if starts[r.pk] else math.inf, r.name)
    )
    row, lengths, unreachable, tried, best = route.fleet_map(), {}, [], set(), math.inf
    for robot in ranked:
        start = starts[robot.pk]
        if start is None or math.dist(start, target) > best + TIE_M:
            break
        length = route.planned_length(robot, start, target, row)
        tried.add(robot.pk)
        if length is None:
            unreachable.append(f"{robot.name} cannot reach {destination.name} (no path fits it)")
            continue
        lengths[robot.pk] = length
        best = min(best, length)
    if not lengths:
        unknown = [robot for robot in ranked if starts[robot.pk] is None]
        if not unknown:
            raise Refused(f"No free robot can reach {destination.name} ({_listed(unreachable)}).")
        return (
            unknown[0],
            "free; its position is not known yet, so how near it is could not be said",
            unreachable,
        )
    tied = [robot for robot in ranked if lengths.get(robot.pk, math.inf) <= best + TIE_M]
    robot = min(tied, key=lambda r: (-(_battery(r, poses) or 0.0), r.name))
    why = f"the nearest free robot, {lengths[robot.pk]:.1f} m to {destination.name}"
    if len(tied) > 1 and _battery(robot, poses) is not None:
        why += f", battery {_battery(robot, poses):.0f}%"
    farther = [
        _distance_words(r, lengths, starts[r.pk], target)
        for r in ranked
        if r is not robot and r.pk not in tried - set(lengths)
    ]
    farther = [words for words in farther if words]
    return robot, why + (f" ({', '.join(farther[:MAX_REASONS])})" if farther else ""), unreachable


def _no_place_words(robot: Robot, free: list[Robot], poses: dict) -> str:
    """Why this robot, for a step with no place to be nearest to ("go home", "rotate"): the fullest battery of
    the free robots, then the first by name."""
    battery = _battery(robot, poses)
    if len(free) == 1:
        return "the only free robot that can do it"
    if battery is not None:
        return f"the fullest battery ({battery:.0f}%) of the {len(free)} free robots that can do it"
    return f"the first by name of the {len(free)} free robots that can do it (none reports its battery)"


def _distance_words(robot: Robot, lengths: dict, start, target) -> str:
    """ "tiago 5.2 m" (planned), "spot 7.9+ m" (not planned: at least its straight line), "" (unknown or no path)."""
    if robot.pk in lengths:
        return f"{robot.name} {lengths[robot.pk]:.1f} m"
    if start is None:
        return ""
    return f"{robot.name} {math.dist(start, target):.1f}+ m"


def _position(robot: Robot, poses: dict) -> tuple[float, float] | None:
    pose = poses.get(robot.pk)
    return (float(pose["x"]), float(pose["y"])) if pose else None


def _battery(robot: Robot, poses: dict) -> float | None:
    """The robot's battery percentage when something reported it (its live pose or its description)."""
    value = (poses.get(robot.pk) or {}).get("battery", robot.description.get("battery"))
    return float(value) if isinstance(value, int | float) else None


@dataclass
class Plan:
    """What plan() decided: each robot's steps, and what the person is told about who was chosen and where."""

    per_robot: dict[Robot, list[dict]]
    notes: list[str] = field(default_factory=list)
    said: dict[int, str] = field(default_factory=dict)  # a step's words as the page's selection made it

    def read_back(self, parse: dict) -> dict:
        """The stored parse with each step the selection gave robots said with them: the console's parse line
        said "a robot the portal chooses" for robots the person had chosen (the interpreter reads the text
        before the selection is applied)."""
        if not self.said:
            return parse
        lines = list(parse.get("read_back") or ())
        lines += [""] * (max(self.said) + 1 - len(lines))
        for index, words in self.said.items():
            lines[index] = words
        return {**parse, "read_back": lines}

    def items(self):
        return self.per_robot.items()


def plan(
    understood: Interpretation,
    user,
    moment=None,
    check_schedule: bool = True,
    selected: list[int] | None = None,
    source: str = "console",
) -> Plan:
    """Split the instruction's steps into each robot's list of steps, or raise Refused (NoneFree: wait).

    selected: robots chosen on the page; a step that names no robot goes to them. Several "any" steps of one
    instruction go to the one robot chosen for the first ("move to A, then to B"). source: the system's
    (access.holds.AUTOMATIC) never moves a robot held by a stop or leased by anyone.
    """
    per_robot: dict[int, list[dict]] = defaultdict(list)
    robots_by_id: dict[int, Robot] = {}
    notes: list[str] = []
    try:
        steps = understood.checked()
    except step_contract.StepError as exc:
        raise Refused(str(exc)) from None
    poses = {
        pk: (p["x"], p["y"], p.get("yaw", 0.0))
        for pk, p in pose_store.known_poses(Robot.objects.only("pk", "start_pose")).items()
    }
    chosen: list[str] | None = _selected_names(selected)
    said: dict[int, str] = {}  # the steps the page's selection gave robots, in words
    for index, checked in enumerate(steps):
        if checked.robots.unnamed and chosen:
            if selected and not said:
                notes.append(chosen_words(chosen, "selected on the page"))
            checked = replace(checked, robots=RobotChoice.named(*chosen))
            if selected:
                said[index] = read_back(checked.to_dict())
        robots, why = resolve_robots(checked, moment, check_schedule, user)
        if checked.robots.mode == ALL or checked.robots.filtered:
            robots = _unheld(robots, notes)
        if why:
            notes.append(why)
            chosen = [robot.name for robot in robots]
        step = checked.to_dict()
        destination = step.get("destination")
        try:
            goals = spots.assign(destination, robots, poses, notes) if destination else {}
        except spots.NoRoom as exc:
            raise Refused(str(exc)) from None
        for robot in robots:
            robots_by_id[robot.pk] = robot
            per_robot[robot.pk].append(
                {**step, "robots": [robot.name], "destination": goals.get(robot.pk, destination)}
            )
    if not per_robot:
        raise Refused("The instruction has no step a robot can do.")
    _check_access(robots_by_id.values(), user, source)
    return Plan({robots_by_id[pk]: steps for pk, steps in per_robot.items()}, notes, said)


def _check_access(robots, user, source: str) -> None:
    """Refused when the system's instruction meets a held or leased robot, or the person may not command one."""
    if holds.is_automatic(source):
        try:
            holds.check_automatic(robots)
        except ControlRefused as exc:
            raise Refused(str(exc)) from None
    if user is not None:
        held_by = leases.holders([robot.pk for robot in robots], known=user)  # one query for all of them
        for robot in robots:
            try:
                check_command(user, robot, held_by.get(robot.pk))
            except ControlRefused as exc:
                raise Refused(str(exc)) from None


def _unheld(robots: list[Robot], notes: list[str]) -> list[Robot]:
    """ "all robots" (or all of a kind) without the robots a stop holds: they are said, or Refused if none is left."""
    rows = Robot.objects.filter(pk__in=[r.pk for r in robots], held_at__isnull=False).select_related(
        "held_by"
    )
    held = {robot.pk: f"{robot.name} is {robot.hold_words}" for robot in rows}
    if not held:
        return robots
    left = [robot for robot in robots if robot.pk not in held]
    words = "; ".join(held.values())
    if not left:
        raise Refused(f"No robot is free now: {words}; name a robot to release it, or release it.")
    notes.append(f"left out: {words} (name it to release it)")
    return left


def _selected_names(selected: list[int] | None) -> list[str] | None:
    """The names of the robots selected on the page, in the order given; Refused for an unknown id."""
    if not selected:
        return None
    found = dict(Robot.objects.filter(pk__in=selected).values_list("pk", "name"))
    unknown = [str(pk) for pk in selected if pk not in found]
    if unknown:
        raise Refused(f"No robot with id {', '.join(unknown)} is registered.")
    return [found[pk] for pk in dict.fromkeys(selected)]


@transaction.atomic
def dispatch(instruction: Instruction, plan: Plan) -> list[Execution]:
    """Create the executions, wake or preempt robots as the state machine says, and queue the instruction
    (its outcome says, until it ends, who was chosen and where they go)."""
    now = timezone.now()
    executions: list[Execution] = []
    per_robot = plan.per_robot
    if not holds.is_automatic(instruction.source):  # a person names the robot: that releases a stop's hold
        released = holds.release(per_robot, instruction.user, why=f"instruction #{instruction.pk}")
        plan.notes += [f"{name} released from its hold ({words})" for name, words in released.items()]
    # each robot's state now, in one query; the executions in one insert (a query or two per robot made a
    # 50-robot instruction's POST take 1.2 to 1.9 s on the cluster at 500 robots: docs/scale.md)
    by_pk = {robot.pk: robot for robot in per_robot}
    for pk, state, link_status in Robot.objects.filter(pk__in=by_pk).values_list(
        "pk", "state", "link_status"
    ):
        by_pk[pk].state, by_pk[pk].link_status = state, link_status
    asleep = [
        pk for pk, robot in by_pk.items() if robot.state in (Robot.State.OFFLINE, Robot.State.REGISTERED)
    ]
    for pk in asleep:
        Robot.objects.transition(pk, Event.LINK_UP, "woken by an instruction", instruction)
    for pk, state in Robot.objects.filter(pk__in=asleep).values_list("pk", "state") if asleep else []:
        by_pk[pk].state = state
    admissions = []
    for robot, steps in per_robot.items():
        priority = step_contract.priority(steps)
        admissions.append(statemachine.admit(robot.state, priority))
        executions.append(
            Execution(instruction=instruction, robot=robot, steps=steps, priority=priority, dispatched_at=now)
        )
    Execution.objects.bulk_create(executions)  # their keys set (PostgreSQL, SQLite: RETURNING)
    preempts = [
        (execution.robot_id, execution.pk)
        for execution, admission in zip(executions, admissions, strict=True)
        if admission == Admission.PREEMPT
    ]
    instruction.robots.set([robot.pk for robot in per_robot])
    outcome = "; ".join(plan.notes)[:4000]
    instruction.parse = plan.read_back(instruction.parse or {})
    Instruction.objects.filter(pk=instruction.pk).update(
        status=Instruction.Status.QUEUED, dispatched_at=now, outcome=outcome, parse=instruction.parse
    )
    instruction.status, instruction.dispatched_at, instruction.outcome = (
        Instruction.Status.QUEUED,
        now,
        outcome,
    )
    robot_ids = [robot.pk for robot in per_robot]
    transaction.on_commit(lambda: _after_commit(robot_ids, preempts))
    return executions


WAITING_NOTE = "waiting for a free robot"
WAIT_LIMIT_S = 600.0  # an instruction waits this long for a free robot, then is refused


def wait(instruction: Instruction, reason: str) -> Instruction:
    """Nobody is free: the instruction stays queued, says what it waits for, and `retry` allocates it later."""
    instruction.status, instruction.outcome = Instruction.Status.QUEUED, f"{WAITING_NOTE}: {reason}"[:4000]
    instruction.save(update_fields=["status", "outcome"])
    return instruction


def waiting():
    """Instructions queued without executions because no robot was free (oldest first)."""
    return Instruction.objects.filter(
        status=Instruction.Status.QUEUED, executions__isnull=True, outcome__startswith=WAITING_NOTE
    ).order_by("received_at")


def retry(now=None) -> list[int]:
    """Allocate the waiting instructions whose robot has become free; refuse those waiting too long.

    Called by the scheduler each tick. Returns the instructions dispatched now.
    """
    now = now or timezone.now()
    dispatched = []
    for pk in list(waiting().values_list("pk", flat=True)[:50]):
        with transaction.atomic():
            instruction = (
                waiting().select_for_update(of=("self",)).filter(pk=pk).select_related("user").first()
            )
            if instruction is not None and _retry_one(instruction, now):
                dispatched.append(pk)
    return dispatched


def _retry_one(instruction: Instruction, now) -> bool:
    """One waiting instruction: dispatch it, keep it waiting (with the reasons now), or refuse it."""
    try:
        dispatch(
            instruction,
            plan(
                Interpretation.from_dict(instruction.parse),
                instruction.user,
                check_schedule=instruction.source != "schedule",
                source=instruction.source,
            ),
        )
        live.instruction(instruction)
        return True
    except NoneFree as exc:
        if (now - instruction.received_at).total_seconds() < WAIT_LIMIT_S:
            if instruction.outcome != f"{WAITING_NOTE}: {exc}"[:4000]:
                live.instruction(wait(instruction, str(exc)))
            return False
        reason = f"no robot became free within {WAIT_LIMIT_S / 60:.0f} min ({exc})"
    except (Refused, ControlRefused) as exc:
        reason = str(exc)
    Instruction.objects.filter(pk=instruction.pk).update(
        status=Instruction.Status.REFUSED, outcome=reason[:4000], finished_at=now
    )
    instruction.refresh_from_db()
    live.instruction(instruction)
    return False


def _after_commit(robot_ids: list[int], preempts: list[tuple[int, int]]) -> None:
    """Raise the preempt flags, then wake the robots' executors (each robot's owner runs its queue under its
    lock, execution/executor.py)."""
    for robot_id, execution_id in preempts:
        coordination.request_preempt(robot_id, execution_id)
    executor.wake(robot_ids)
