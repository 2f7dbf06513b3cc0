"""The make_way step's traffic: where a robot asked to make way stands aside (off the route of the robot that
asked, clear of everyone), and when that robot has passed, so it may go back (execution.handlers.make_way drives
it there and back). Who is asked, and the request itself, are traffic's (execution.traffic, traffic_state).
"""

from __future__ import annotations

import itertools
import math
import time

from execution import blocking, coordination, route, traffic
from execution import traffic_fleet as fleet
from execution import traffic_state as state
from execution.steps import Session
from fleetcore import traffic as plain
from fleetcore import traffic_tuning as tune
from robots.models import Robot


def aside(robot: Robot, here, request: dict) -> tuple[float, float] | None:
    """The free spot nearest to `here` where the robot stands clear of the route it makes way for (by both
    robots' reach and the planning margins) and of the robots standing and the goals reserved; None when
    there is none within ASIDE_SEARCH_M."""
    planner = route.planner_for(robot, turning=True)  # it turns there, to come back
    radius, route_points = fleet.reach(robot), [tuple(p) for p in request["route"]]
    clear = request["r"] + radius + tune.CLAIM_MARGIN + tune.PLAN_MARGIN
    legs = list(itertools.pairwise(route_points)) or [(route_points[0], route_points[0])]

    def is_free(x: float, y: float) -> bool:
        if planner is not None and not planner.free(*planner.to_cell(x, y)):
            return False
        return all(plain.segment_distance((x, y), (x, y), a, b) >= clear for a, b in legs)

    _, still = traffic.obstacles(coordination.connection(), robot.pk, time.time(), {request["for"]})
    discs = [capsule for capsule, _ in still if int(capsule.label) != request["for"]]  # stretches held, whole
    return plain.free_spot(
        tuple(here), radius, discs, is_free, prefer=tuple(here), step=tune.ASIDE_STEP, search_m=tune.ASIDE_SEARCH_M,
        margin=tune.CLAIM_MARGIN + tune.PLAN_MARGIN,
    )  # fmt: skip


async def until_passed(session: Session, request: dict, home) -> float:
    """Wait, standing aside, until the robot made way for has passed `home` (it has a plan, none of whose
    cells near `home` lies ahead of where its claim starts, in the plan's order, and its claim is clear of
    it; a robot waiting to plan again has not passed), is done with its instruction or waits for this
    one where it stands aside; at most MAKE_WAY_WAIT_S. Returns the seconds waited. (Judged by the clock, a
    robot held up by the claims had "passed" as soon as its plan's times had: robots came back after 0 s
    in runs ad and ae.)"""
    redis, other, started = coordination.connection(), request["for"], time.monotonic()
    near = fleet.reach(session.robot) + plain.TRAFFIC_CELL
    clear = request["r"] + fleet.reach(session.robot) + tune.CLAIM_MARGIN
    await session.link.halt()
    while time.monotonic() - started < tune.MAKE_WAY_WAIT_S:
        if await blocking.call(_passed, redis, session.robot.pk, other, home, near, clear):
            break
        deadline = time.monotonic() + tune.MAKE_WAY_POLL_S
        while time.monotonic() < deadline:
            session.check()
            await session.pose()
    return time.monotonic() - started


def _passed(redis, robot_id: int, other: int, home, near: float, clear: float) -> bool:
    """Whether the robot made way for (other) has passed `home`, is done, or waits for this one (until_passed)."""
    if not fleet.is_busy(other):
        return True  # done with its instruction
    plans, claims, waits = state.read_all(redis, "plans", "claims", "waits")
    now = time.time()
    if waits.get(other, {}).get("for") == robot_id:
        return True  # its way now goes through the spot aside (run af: each waited for the other for 120 s)
    if other not in plans:  # (between two plans, or two tries of a stalled trip, it has not passed: run w)
        return False
    held, cells = claims.get(other), plans[other]["cells"]
    at = _plan_time_at(cells, held["a"]) if held else None
    at = now if at is None else at  # where the plan has it now (a robot late on it: run ae)
    ahead = any(t0 > at and math.dist(plain.center_of((col, row)), home) < near for col, row, t0, _ in cells)
    return not ahead and (held is None or plain.segment_distance(home, home, held["a"], held["b"]) > clear)


def _plan_time_at(cells, point) -> float | None:
    """When a plan's reserved cells first have the robot at `point` (its cell or one next to it); None when
    the plan does not pass there."""
    times = [
        t0 for col, row, t0, _ in cells if math.dist(plain.center_of((col, row)), point) < plain.TRAFFIC_CELL
    ]
    return min(times, default=None)
