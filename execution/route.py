"""Routes on the fleet's map for robots without a navigation stack: around walls and obstacles, not through.

The paper's Figure 7 drives straight at the goal; a robot then stops at the first obstacle between. Here the
portal plans on the occupancy grid it already has (fleetcore.planning, the same A* the simulated nav stacks use),
inflated by the robot's footprint, and the Figure 7 controller drives leg by leg.
"""

from __future__ import annotations

import functools
import itertools
import logging
import math

from django.conf import settings

from execution.models import Execution
from fleetcore.mapfile import OccupancyGrid
from fleetcore.planning import Planner
from places.models import Map
from robots import poses as pose_store
from robots.models import Robot

log = logging.getLogger(__name__)

DEFAULT_RADIUS = 0.15  # m, when a robot has no footprint
NEARBY_M = 6.0  # robots farther than this from the start will have moved by the time we get there


def extents(footprint) -> tuple[float, float] | None:
    """(x extent, y extent) of a footprint polygon [[x, y], ...]; None for no usable polygon."""
    try:
        xs, ys = [float(p[0]) for p in footprint], [float(p[1]) for p in footprint]
    except (TypeError, ValueError, IndexError):
        return None
    if len(xs) < 3:
        return None
    return max(xs) - min(xs), max(ys) - min(ys)


def footprint_radius(footprint) -> float:
    """Half the smaller extent of the footprint polygon: the radius the robot needs to pass a gap."""
    size = extents(footprint)
    return min(size) / 2 if size else DEFAULT_RADIUS


def reach_radius(footprint) -> float:
    """Half the footprint's diagonal: the disc another robot's corners may sweep (a Husky is 1 m long)."""
    size = extents(footprint)
    return math.hypot(*size) / 2 if size else DEFAULT_RADIUS


def fleet_map() -> Map | None:
    """The map robots move on: the current world's, else the newest one."""
    return (
        Map.objects.filter(name=settings.FLEET_WORLD).first() or Map.objects.order_by("-created_at").first()
    )


@functools.lru_cache(maxsize=16)
def _planner(map_id: int, version: str, radius: float) -> Planner:
    """One planner per map version and robot size, per process (building one inflates the whole grid)."""
    row = Map.objects.get(pk=map_id)
    grid = OccupancyGrid(
        row.resolution, row.width, row.height, (row.origin_x, row.origin_y, row.origin_yaw), row.cells()
    )
    return Planner(grid, radius)


def planner_for(robot, row: Map | None = None, turning: bool = False) -> Planner | None:
    """The planner for this robot's size on the fleet map (row: the map, when the caller has it); None: no map.
    Its grid is inflated by half the robot's narrow side (the room it needs to pass a gap), or, turning, by half
    its diagonal (the disc its corners sweep as it turns on the spot)."""
    row = row or fleet_map()
    if row is None:
        return None
    radius = (reach_radius if turning else footprint_radius)(robot.footprint)
    return _planner(row.pk, row.created_at.isoformat(), round(radius, 2))


def path_length(start: tuple[float, float], path: list[tuple[float, float]]) -> float:
    """Metres along the waypoints from start."""
    return sum(math.dist(a, b) for a, b in itertools.pairwise([start, *path]))


def planned_length(robot, start, goal, row: Map | None = None) -> float | None:
    """Length of the route the robot would drive from start to goal (m): the straight line without a map,
    None when no path fits the robot (walls, or too narrow a gap for its footprint)."""
    planner = planner_for(robot, row)
    if planner is None:
        return math.dist(start, goal)
    path = planner.plan(tuple(start), tuple(goal))
    return None if path is None else path_length(tuple(start), path)


def robots_in_the_way(robot, start: tuple[float, float]) -> list[tuple[float, float, float]]:
    """Other robots near the start as discs (x, y, radius): where the links process last saw them, and where
    those under way are going (they will stand there when we pass)."""
    others = {r.pk: r for r in Robot.objects.exclude(pk=robot.pk).only("pk", "footprint")}
    spots = [(pk, pose["x"], pose["y"]) for pk, pose in pose_store.last_poses(others).items()]
    _, goals = Execution.objects.current_work(list(others), running_only=True)
    spots += [(pk, goal["x"], goal["y"]) for pk, goal in goals.items()]
    return [
        (x, y, reach_radius(others[pk].footprint))
        for pk, x, y in spots
        if math.dist(start, (x, y)) < NEARBY_M
    ]


def route(robot, start: tuple[float, float], goal: tuple[float, float]) -> list[tuple[float, float]]:
    """Waypoints from start to goal around what the map shows and the robots parked near; [goal] without a map."""
    row = fleet_map()
    if row is None:
        return [goal]
    planner = planner_for(robot, row)
    others = robots_in_the_way(robot, start)
    path = (planner.plan(start, goal, avoid=others) if others else None) or planner.plan(start, goal)
    if path is None:
        log.warning(
            "%s: no free path on map %s from %s to %s; driving straight", robot.name, row.name, start, goal
        )
        return [goal]
    return path
