"""Goal spots: where each robot of an instruction stops, so that no two robots end on one spot.

A place is taken when a robot is parked on it (its last pose, for robots not under way) or is another robot's
goal (the destination of a running or queued execution). A robot sent to a taken place goes to the nearest free
spot around it, clear of the other robots' footprints and on free ground for its own size, and the person is
told ("A is taken by robot1: husky goes to a free spot 0.6 m east of A"). Several robots sent to one place get
spots on a ring around it in the cyclic order of their bearings, so that their paths do not cross needlessly.
"""

from __future__ import annotations

import math

from execution import route
from execution.models import Execution
from fleetcore.traffic import Disc, clear_of, compass, free_spot
from robots.models import Robot

RING_MARGIN = 0.35  # metres between neighbouring robots on the ring
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
        }
    return goals


def taken(exclude_ids, poses: dict) -> list[Disc]:
    """What takes room at the goals now: other robots' goals (running or queued), and where the others that
    are not under way stand."""
    others = {
        r.pk: r for r in Robot.objects.exclude(pk__in=list(exclude_ids)).only("pk", "name", "footprint")
    }
    _, goals = Execution.objects.current_work(list(others))
    discs = []
    for pk, robot in others.items():
        if pk in goals:
            goal = goals[pk]
            discs.append(Disc(float(goal["x"]), float(goal["y"]), radius_of(robot), f"{robot.name}'s goal"))
        elif pk in poses:
            x, y, _ = poses[pk]
            discs.append(Disc(float(x), float(y), radius_of(robot), robot.name))
    return discs


def assign(destination: dict, robots: list[Robot], poses: dict, notes: list[str]) -> dict[int, dict]:
    """Each robot's goal for a step to this destination: its ring spot (several robots) or the place itself,
    moved when taken to the nearest free spot where it can turn on the spot, else stand; what was moved is
    told in notes. NoRoom when nothing is free."""
    place = destination.get("name") or "the goal"
    center = (float(destination["x"]), float(destination["y"]))
    wanted = ring_goals(destination, robots, poses) if len(robots) > 1 else {robots[0].pk: dict(destination)}
    others = taken([robot.pk for robot in robots], poses)
    row, by_id, out = route.fleet_map(), {robot.pk: robot for robot in robots}, {}
    for pk, goal in wanted.items():
        robot, radius, point = by_id[pk], radius_of(by_id[pk]), (goal["x"], goal["y"])
        is_free = _ground(robot, row)
        blocker = clear_of(point, radius, others)
        here = tuple(poses[pk][:2]) if pk in poses else None
        spot = point
        if blocker is not None or not is_free(*point):
            spot = free_spot(
                point, radius, others, _ground(robot, row, turning=True), prefer=here
            ) or free_spot(point, radius, others, is_free, prefer=here)
            if spot is None:
                raise NoRoom(f"{place} is taken and no spot around it is free for {robot.name}.")
        stays = here is not None and _already_there(here, spot, center, radius, others, is_free)
        if stays:
            spot = (round(here[0], 3), round(here[1], 3))
        out[pk] = goal if spot == point else {**goal, "x": spot[0], "y": spot[1], "around": place}
        if spot != point and (not stays or math.dist(spot, point) >= STAY_SLACK_M):
            notes.append(_moved(place, center, blocker, robot, spot, stays))
        others.append(Disc(out[pk]["x"], out[pk]["y"], radius, f"{robot.name}'s goal"))
    return out


def _already_there(here, spot, center, radius: float, others: list[Disc], is_free) -> bool:
    """Whether a robot is to stay where it stands rather than go to `spot`: it stands free of the others and
    their goals, where it may stand, no farther from the place than that spot (within STAY_SLACK_M). Tried as a
    user: "move husky1, husky2 and tb05 to Cross" said twice moved husky2, parked by a rack after the first,
    to another spot a metre off, and it stalled turning by the rack three times."""
    near = math.dist(here, center) <= math.dist(spot, center) + STAY_SLACK_M
    return near and clear_of(here, radius, others) is None and is_free(*here)


def _ground(robot: Robot, row, turning: bool = False):
    """Whether a robot of this size may stand at (x, y) on the fleet map (anywhere, without a map); turning:
    and turn there on the spot (a spot found for it, when the place is taken: a Husky sent to one 0.64 m
    from a rack's corner stalled turning into it, tried as a user)."""
    planner = route.planner_for(robot, row, turning=turning)
    if planner is None:
        return lambda x, y: True
    return lambda x, y: planner.free(*planner.to_cell(x, y))


def _moved(place: str, center, blocker: Disc | None, robot: Robot, spot, stays: bool = False) -> str:
    why = f"{place} is taken by {blocker.label}" if blocker else f"{place} has no room for {robot.name}"
    distance = math.dist(center, spot)
    where = f"{distance:.1f} m {compass(center, spot)} of {place}" if distance >= 0.05 else f"at {place}"
    if stays:  # (already by the place: it needs no reason unless the place is taken)
        return f"{why + ': ' if blocker else ''}{robot.name} stays where it stands, {where}"
    return f"{why}: {robot.name} goes to a free spot {where}"
