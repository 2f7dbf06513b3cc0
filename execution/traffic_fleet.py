"""Traffic's database queries: who stands where (standing), who is busy with an instruction, whom a stop or a
lease keeps still, what a robot runs now, and the radius a robot takes in traffic (reach).

Plain reads of the robots' and executions' tables and of the pose store; handed the traffic table's entries
where it needs them (the parked robots), it keeps no state of its own and imports none.
"""

from __future__ import annotations

import math

from access import leases
from execution import route, spots
from execution.models import Execution
from fleetcore import traffic as plain
from fleetcore import traffic_tuning as tune
from robots import poses as pose_store
from robots.models import Robot

BUSY = ("running", "queued")  # an execution in these states: its robot is about to move, or moves


def reach(robot: Robot) -> float:
    """The radius a robot takes in traffic: the farthest corner of its footprint from its centre (as goal spots
    count it), plus a margin."""
    return spots.radius_of(robot) + tune.RESERVE_MARGIN


def standing(parked: dict[int, dict], exclude: set[int]) -> list[tuple[plain.Capsule, float]]:
    """Robots not under traffic control, as discs standing since ever: their live pose, else where they parked
    (`parked`: the traffic table's entries, {id: {"x", "y"}}), else their start pose. As far as the table
    knows, these stand where they are for good."""
    others = {
        r.pk: r for r in Robot.objects.exclude(pk__in=list(exclude)).only("pk", "footprint", "start_pose")
    }
    live_poses = pose_store.last_poses(list(others))
    out = []
    for pk, robot in others.items():
        pose = live_poses.get(pk) or parked.get(pk) or pose_store.start_of(robot)
        if pose is not None:
            point = (float(pose["x"]), float(pose["y"]))
            out.append((plain.Capsule(point, point, reach(robot), str(pk)), -math.inf))
    return out


def name_of(robot_id: int) -> str:
    """A robot's name for the log and the map ("#<id>" once it is gone)."""
    return Robot.objects.filter(pk=robot_id).values_list("name", flat=True).first() or f"#{robot_id}"


def busy_ids() -> set[int]:
    """Robots with an execution running or queued: one standing now is about to move, not parked."""
    return set(Execution.objects.filter(status__in=BUSY).values_list("robot_id", flat=True))


def is_busy(robot_id: int) -> bool:
    """Whether one robot is busy (busy_ids), asked of it alone."""
    return Execution.objects.filter(robot_id=robot_id, status__in=BUSY).exists()


def kept_still() -> set[int]:
    """Robots nothing automatic may move: held by a stop, or leased by someone (access.holds)."""
    held = set(Robot.objects.filter(held_at__isnull=False).values_list("pk", flat=True))
    return held | {lease.robot_id for lease in leases.active(Robot.objects.all())}


def held_in_the_way(robot: Robot, start, goal) -> str:
    """ "; tb12, held by a stop (admin, 10:43:44), stands in the way": the robots kept still (kept_still) on
    the map route from start to goal (robots ignored), for the words of a trip that found no plan; "" if none."""
    planner = route.planner_for(robot)
    through = (planner.plan(tuple(start[:2]), tuple(goal[:2])) if planner else None) or [tuple(goal[:2])]
    through = [tuple(start[:2]), *through]
    rows = Robot.objects.filter(pk__in=kept_still() - {robot.pk}).select_related("held_by")
    poses = pose_store.last_poses([r.pk for r in rows])
    words = [
        f"{r.name}, {r.hold_words or 'under a control lease'},"
        for r in rows
        if r.pk in poses and plain.passes(through, _disc(r, poses[r.pk]), reach(robot))
    ]
    return f"; {' and '.join(words)} stands in the way" if words else ""


def _disc(robot: Robot, pose: dict) -> plain.Capsule:
    point = (float(pose["x"]), float(pose["y"]))
    return plain.Capsule(point, point, reach(robot), str(robot.pk))


def running(robot: Robot) -> str:
    """ ", instruction #14 by admin": what the robot runs now and whose it is (a cause's words)."""
    running = Execution.objects.filter(robot=robot, status="running").select_related("instruction__user")
    execution = running.first()
    if execution is None:
        return ""
    instruction = execution.instruction
    by = instruction.user.username if instruction.user else f"the system ({instruction.source})"
    return f", instruction #{instruction.pk} by {by}"
