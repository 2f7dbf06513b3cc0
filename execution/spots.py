"""Goal spots: where each robot of an instruction stops, so that no two robots end on one spot.

A place is taken when a robot is parked on it (its last pose, for robots not under way) or is another robot's
goal (the destination of a running or queued execution). A robot sent to a taken place goes to the nearest free
spot around it, clear of the other robots' footprints and on free ground for its own size, and the person is
told ("A is taken by robot1: husky goes to a free spot 0.6 m east of A"). Several robots sent to one place get
spots on a ring around it in the cyclic order of their bearings, so that their paths do not cross needlessly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from execution import route
from execution.models import Execution
from fleetcore.traffic import Disc, clear_of, compass, free_spot
from robots.models import Robot

RING_MARGIN = 0.35  # metres between neighbouring robots on the ring
KEEP_OPEN_M = 4.0  # m from the place: the goals of robots on their way there are kept open to them
WALL_TRIES = 16  # free spots tried for a robot before none is found that walls nobody off
IN_THE_WAY_M = 1.0  # m between two discs: the other one is named among those in the way
WALL_NEAR_M = 2.5  # m: goals farther from a spot than this are not walled off by it (none is looked at)
STAY_SLACK_M = 0.1  # m a robot standing free by a place may be farther from it than its spot, and stay
UNKNOWN_RADIUS = 0.3  # m, a robot without a footprint


class NoRoom(ValueError):
    """No free spot near the place; the message says so in words."""


def radius_of(robot: Robot) -> float:
    """The largest distance from the robot's centre to a corner of its footprint (the disc it may sweep)."""
    points = robot.footprint or []
    try:
        return max(math.hypot(float(x), float(y)) for x, y in points) if points else UNKNOWN_RADIUS
    except (TypeError, ValueError):
        return UNKNOWN_RADIUS


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
            "center": [cx, cy],
            "taken_by": f"the {n} robots sent there together",
        }
    return goals


@dataclass(frozen=True)
class Heading:
    """A robot on its way to a goal (its disc there) from where it is: no spot given after it may wall it off."""

    robot: Robot
    start: tuple[float, float]
    goal: Disc


def taken(exclude_ids, poses: dict) -> tuple[list[Disc], list[Heading]]:
    """What takes room at the goals now: other robots' goals (running or queued), and where the others that
    are not under way stand; and the robots on their way to those goals (from where they are)."""
    others = {
        r.pk: r for r in Robot.objects.exclude(pk__in=list(exclude_ids)).only("pk", "name", "footprint")
    }
    _, goals = Execution.objects.current_work(list(others))
    discs, heading = [], []
    for pk, robot in others.items():
        if pk in goals:
            goal = goals[pk]
            disc = Disc(float(goal["x"]), float(goal["y"]), radius_of(robot), f"{robot.name}'s goal")
            discs.append(disc)
            if pk in poses:
                heading.append(Heading(robot, tuple(map(float, poses[pk][:2])), disc))
        elif pk in poses:
            x, y, _ = poses[pk]
            discs.append(Disc(float(x), float(y), radius_of(robot), robot.name))
    return discs, heading


def assign(destination: dict, robots: list[Robot], poses: dict, notes: list[str]) -> dict[int, dict]:
    """Each robot's goal for a step to this destination: its ring spot (several robots) or the place itself,
    moved when taken to the nearest free spot where it can turn on the spot, else stand; what was moved is
    told in notes. NoRoom when nothing is free."""
    place = destination.get("name") or "the goal"
    center = (float(destination["x"]), float(destination["y"]))
    wanted = ring_goals(destination, robots, poses) if len(robots) > 1 else {robots[0].pk: dict(destination)}
    others, heading = taken([robot.pk for robot in robots], poses)
    heading = [h for h in heading if math.dist((h.goal.x, h.goal.y), center) < KEEP_OPEN_M]
    row, by_id, out = route.fleet_map(), {robot.pk: robot for robot in robots}, {}
    for pk, goal in wanted.items():
        robot, radius, point = by_id[pk], radius_of(by_id[pk]), (goal["x"], goal["y"])
        is_free = ground(robot, row)
        here = tuple(poses[pk][:2]) if pk in poses else None
        blocker = clear_of(point, radius, others)
        why = _why(place, robot, blocker, is_free(*point))
        why = why or _walls(robot, point, here, others, heading, row)
        spot = point
        if why:
            spot, walled = _reachable_spot(robot, point, radius, others, heading, here, row)
            if spot is None:
                raise NoRoom(f"{why}, and no spot around {place} is free for {robot.name}{walled}.")
        stays = here is not None and _already_there(here, spot, center, radius, others, is_free)
        if stays:
            spot = (round(here[0], 3), round(here[1], 3))
        out[pk] = goal if spot == point else _spot(goal, spot, place, center, blocker)
        if spot != point and (not stays or math.dist(spot, point) >= STAY_SLACK_M):
            notes.append(_moved(place, center, why, robot, spot, stays, blocker is not None))
        others.append(Disc(out[pk]["x"], out[pk]["y"], radius, f"{robot.name}'s goal"))
        if here is not None:  # the spots given after this one leave its way in open
            heading.append(Heading(robot, here, others[-1]))
    return out


def _why(place: str, robot: Robot, blocker: Disc | None, on_free_ground: bool) -> str:
    """Why the robot cannot have the point it was meant for, in words ("" when it can, as far as this says)."""
    if blocker is not None:
        return f"{place} is taken by {blocker.label}"
    return "" if on_free_ground else f"{place} has no room for {robot.name}"


def _reachable_spot(
    robot: Robot, point, radius: float, others: list[Disc], heading: list[Heading], here, row
):
    """(the nearest free spot to point that the robot can get to past the others and their goals, and that
    walls off the way in to nobody's goal; "") or (None, " (what was in the way of the last one tried)").
    Where it can turn on the spot, else where it can stand."""
    turning, standing = ground(robot, row, turning=True), ground(robot, row)
    rejected, walled = [], ""
    for _ in range(WALL_TRIES):
        around = others + rejected
        spot = free_spot(point, radius, around, turning, prefer=here) or free_spot(
            point, radius, around, standing, prefer=here
        )
        if spot is None:
            break
        why = _walls(robot, spot, here, others, heading, row)
        if not why:
            return spot, ""
        rejected.append(Disc(spot[0], spot[1], 0.0))
        walled = f" ({why})"
    return None, walled


def _walls(robot: Robot, spot, here, others: list[Disc], heading: list[Heading], row) -> str:
    """Why the robot may not have this spot ("" when it may): it cannot get there from where it is past the
    others and their goals, or standing there it would wall off another robot's way to its goal. Only where
    the others make the difference (a way the map alone has not, the map's own matter, is no one's fault).
    Only goals within WALL_NEAR_M are looked at (each look is a plan). Four robots sent to A one by one: husky, given A, could never get in past the spots given after it to
    the others (it failed after 139 s, "no plan to its goal clear of the others"), tried as an operator."""
    mine = Disc(spot[0], spot[1], radius_of(robot), f"{robot.name}'s goal")
    near = lambda disc: math.dist((disc.x, disc.y), spot) < WALL_NEAR_M  # noqa: E731
    crowded = any(near(disc) for disc in others)
    if here is not None and crowded and not _reaches(robot, here, spot, others, row):
        near = [d.label for d in others if math.dist((d.x, d.y), spot) < d.r + mine.r + IN_THE_WAY_M]
        return f"{robot.name} cannot get to it past {_and(near) or 'the other robots'}"
    for other in (other for other in heading if near(other.goal)):
        rest = [d for d in others if d is not other.goal]
        goal = (other.goal.x, other.goal.y)
        if not _reaches(other.robot, other.start, goal, [*rest, mine], row) and _reaches(
            other.robot, other.start, goal, rest, row
        ):
            return f"{robot.name} there would wall off {other.goal.label}"
    return ""


def _reaches(robot: Robot, start, goal, discs: list[Disc], row) -> bool:
    """Whether the robot can plan a way from start to goal round these discs, or the map alone has none."""
    planner = route.planner_for(robot, row)
    if planner is None:
        return True
    if planner.plan(tuple(start), tuple(goal), avoid=[(d.x, d.y, d.r) for d in discs]) is not None:
        return True
    return planner.plan(tuple(start), tuple(goal)) is None


def _and(names: list[str]) -> str:
    return ", ".join(names[:-1]) + f" and {names[-1]}" if len(names) > 1 else "".join(names)


def _spot(goal: dict, spot, place: str, center, blocker: Disc | None) -> dict:
    """The goal moved to a free spot next to the place: where and who took the place go with it, for the words
    on where the robot ends (fleetcore.outcomes)."""
    taken_by = blocker.label if blocker else goal.get("taken_by")
    return {**goal, "x": spot[0], "y": spot[1], "around": place, "center": list(center), "taken_by": taken_by}


def _already_there(here, spot, center, radius: float, others: list[Disc], is_free) -> bool:
    """Whether a robot is to stay where it stands rather than go to `spot`: it stands free of the others and
    their goals, where it may stand, no farther from the place than that spot (within STAY_SLACK_M). Tried as a
    user: "move husky1, husky2 and tb05 to Cross" said twice moved husky2, parked by a rack after the first,
    to another spot a metre off, and it stalled turning by the rack three times."""
    near = math.dist(here, center) <= math.dist(spot, center) + STAY_SLACK_M
    return near and clear_of(here, radius, others) is None and is_free(*here)


def ground(robot: Robot, row=None, turning: bool = False):
    """Whether a robot of this size may stand at (x, y) on the fleet map (row; None: read it), anywhere without
    a map; turning:
    and turn there on the spot (a spot found for it, when the place is taken: a Husky sent to one 0.64 m
    from a rack's corner stalled turning into it, tried as a user)."""
    planner = route.planner_for(robot, row, turning=turning)
    if planner is None:
        return lambda x, y: True
    return lambda x, y: planner.free(*planner.to_cell(x, y))


def _moved(place: str, center, why: str, robot: Robot, spot, stays: bool = False, taken: bool = True) -> str:
    distance = math.dist(center, spot)
    where = f"{distance:.1f} m {compass(center, spot)} of {place}" if distance >= 0.05 else f"at {place}"
    if stays:  # (already by the place: it needs no reason unless the place is taken)
        return f"{why + ': ' if taken else ''}{robot.name} stays where it stands, {where}"
    return f"{why}: {robot.name} goes to a free spot {where}"
