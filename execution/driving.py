"""The driving loop of a route under traffic: plan (execution.traffic), then stretch by stretch, each claimed
first, drive it (the route driver) or hand it to the robot's nav stack (execution.steps); back off to break a
deadlock, hold where the plan waits, and plan again round a robot standing in the way.

A robot keeps to its plan's times (it never sets off on a stretch well before the plan says), and its plan is
never replanned on the way: the claims keep the plans' order however late it runs (execution.traffic, 2.).
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
import time

import live
from execution import blocking, coordination, route, traffic
from execution import traffic_fleet as fleet
from execution import traffic_state as state
from execution.steps import STALL_S, Aborted, Session, StepFailed, drive, navigate, travel_time
from fleetcore import motion
from fleetcore import traffic as plain
from fleetcore import traffic_tuning as tune
from fleetcore.speed import Pace

log = logging.getLogger(__name__)


def stretches(path: list[tuple]) -> list[tuple]:
    """The route cut into stretches of at most LEG_M: [(x, y, t, hold)], hold True for a planned wait."""
    out = []
    for a, b in itertools.pairwise(path):
        if a[:2] == b[:2]:
            out.append((*b, True))
            continue
        n = max(1, math.ceil(math.dist(a[:2], b[:2]) / tune.LEG_M))
        for i in range(1, n + 1):
            f = i / n
            out.append((a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f, False))
    return out


async def travel(session: Session, goal, pace: Pace, nav: bool = False) -> tuple[float, float]:
    """Drive (or, with its own nav stack, navigate) the robot to goal along a reserved route, stretch by
    stretch, each claimed first; replan around a deadlock or a robot standing in the way.

    Returns the spot it was to stop at: the goal, or the free spot next to it when a robot stood on the goal
    (where it really stopped is judged from its pose: fleetcore.outcomes)."""
    robot = session.robot
    await _measure_clock(session)
    around: set[int] = set()
    reroutes, gave_way, settles, stuck_since = 0, 0, 0, None
    here = (await session.pose())[:2]
    # under traffic from now on: others wait for it, not go round it
    await blocking.call(traffic.claim, robot, here, here, session.check)
    try:
        spot = tuple(goal)  # where it stops: the goal, or a free spot next to it (the first plan says)
        for replans in range(tune.MAX_REPLANS):
            pose = await session.pose()
            learned = await blocking.call(state.known_pace, robot.pk) if nav else None
            speed = pace.planned(nav, learned) * session.link.clock.rate  # m per second of wall time
            settled = replans > 0 and spot != tuple(goal)
            path = await traffic.plan(
                robot, pose[:2], spot, speed, around, session.check, settled,
                may_ask=True, first=session.making_way,
            )  # fmt: skip
            if path is None:  # it stands (for good, as the others plan) until a way opens
                await blocking.call(state.drop_plan, robot)
                stuck_since = stuck_since or time.monotonic()
                if time.monotonic() - stuck_since > tune.WAIT_LIMIT_S:
                    in_the_way = await blocking.call(fleet.held_in_the_way, robot, pose, spot)
                    raise StepFailed(f"{robot.name}: no plan to its goal clear of the others{in_the_way}")
                await _hold(session, time.time() + tune.PLAN_AGAIN_S)
                continue
            stuck_since, spot = None, tuple(path[-1][:2])
            try:
                await _follow(session, path, pace, nav, frozenset(around))
                done = math.dist(spot, goal) < tune.SETTLE_M or settles >= tune.SETTLE_TRIES
                if done or not await _passed(session, spot):
                    return spot
                settles, spot = settles + 1, tuple(goal)  # its goal may be free by now: again
            except traffic.Reroute as exc:
                gave_way, reroutes = gave_way + exc.gave_way, reroutes + (not exc.gave_way)
                if reroutes > tune.MAX_REROUTES:
                    raise StepFailed(
                        f"{robot.name}: no way through after {tune.MAX_REROUTES} reroutes"
                    ) from None
                if gave_way > tune.MAX_GIVE_WAYS:
                    raise StepFailed(
                        f"{robot.name}: no way through: it gave way {tune.MAX_GIVE_WAYS} times in deadlocks"
                    ) from None
                around |= exc.around
                await _back_off(session, exc.around, pace, nav)
                here = (await session.pose())[:2]
                # keep only where it stands: the others may go on
                await blocking.call(traffic.claim, robot, here, here, session.check)
        raise StepFailed(f"{robot.name}: not there after {tune.MAX_REPLANS} plans")
    finally:
        await blocking.call(state.release, robot, session.link.poses.value)


async def _passed(session: Session, spot) -> bool:
    """Whether the robots under way that have yet to pass near the free spot where this one stopped
    (traffic.yet_to_pass: it does not plan again from there before them) pass within PASS_WAIT_S; then it
    plans again for its goal, which they may have left. It waits at rest, holding the room it stands in; one of
    them waiting for it (its claim: its plan had this one gone by now) ends the wait: it plans for its goal at
    once, which takes it off that one's way (a swap whose third robot crossed the spot, run under load)."""
    robot, redis = session.robot, coordination.connection()
    deadline = time.monotonic() + tune.PASS_WAIT_S
    while await blocking.call(traffic.yet_to_pass, robot, spot):
        if await blocking.call(state.waiting_for, redis, robot.pk):
            log.info(
                "traffic: %s at its free spot %s is in another's way: it plans for its goal", robot.name, spot
            )
            return True  # off that one's way, to where it was sent (the plan heeds that one's reservation)
        if time.monotonic() > deadline:
            log.info("traffic: %s stays at its free spot %s: robots yet to pass it after %.0f s", robot.name, spot,
                     tune.PASS_WAIT_S)  # fmt: skip
            return False
        session.check()
        await blocking.call(state.renew, redis, robot.pk)
        await asyncio.sleep(tune.WAIT_POLL_S)
        await (
            session.pose()
        )  # a robot waiting still reads where it is (and odometry that stops fails the step)
    return True


async def _back_off(session: Session, others: set[int], pace: Pace, nav: bool) -> None:
    """Give way to the robots of a deadlock: drive BACK_OFF_M straight away from them (or half or a quarter
    turn aside), where the map is free and the claim is granted, so the plan round them starts with room to
    pass; two robots stopped nose to nose are too close for any first stretch of a way round to be granted
    (the claims let nobody come nearer). Nowhere to go: it replans where it stands."""
    robot, redis = session.robot, coordination.connection()
    here = (await session.pose())[:2]
    claims = await blocking.call(state.read, redis, "claims")
    held = [plain.entry_capsule(pk, entry) for pk, entry in claims.items() if pk in others]
    for target in give_way(here, held, await blocking.call(route.planner_for, robot)):
        if await blocking.call(traffic.claim, robot, here, target, session.check) is not None:
            continue
        log.info("traffic: %s backs off to %s to give way to %s", robot.name, target, sorted(others))
        try:
            if nav:
                await navigate(session, *target, travel_time(tune.BACK_OFF_M * 2, math.pi, pace.stack_limits))
            else:
                controller = motion.GoToGoal(target, pace.limits, tune.CORNER_TOLERANCE)
                await drive(
                    session,
                    controller,
                    travel_time(tune.BACK_OFF_M, math.pi, pace.limits),
                    stall_s=STALL_S,
                )
        except StepFailed as exc:  # it got part of the way, or none: the plan starts from where it is
            log.info("traffic: %s backed off only so far (%s)", robot.name, exc)
        return


def give_way(here, held: list[plain.Capsule], planner) -> list[tuple[float, float]]:
    """Where a robot at `here` may back off to from the room others hold: BACK_OFF_M straight away from them,
    else half or a quarter turn aside, on free ground (the planner's map, when there is one)."""
    away = [0.0, 0.0]
    for other in held:
        point = plain.nearest_on(here, other.a, other.b)
        d = math.dist(here, point) or 1e-9
        away[0], away[1] = away[0] + (here[0] - point[0]) / d, away[1] + (here[1] - point[1]) / d
    if away == [0.0, 0.0]:
        return []
    heading, out = math.atan2(away[1], away[0]), []
    for turn in (0.0, math.pi / 4, -math.pi / 4, math.pi / 2, -math.pi / 2):
        target = (
            here[0] + tune.BACK_OFF_M * math.cos(heading + turn),
            here[1] + tune.BACK_OFF_M * math.sin(heading + turn),
        )
        if planner is None or planner.free(*planner.to_cell(*target)):
            out.append(target)
    return out


async def _measure_clock(session: Session) -> None:
    """Read odometry until the robot's clock rate is known (a link opened just now has not measured it), so
    its plan is timed at its real pace; a robot whose stamps say nothing is planned at rate 1."""
    deadline = time.monotonic() + 3 * motion.RATE_SPAN_S
    while not session.link.clock.measured and time.monotonic() < deadline:
        await session.pose()
        session.check()


async def _follow(session: Session, path, pace: Pace, nav: bool, gone_round: frozenset = frozenset()) -> None:
    """Drive the planned path stretch by stretch, each claimed first; the goal is the path's end (the goal
    asked for, or the free spot next to it when that was taken). The plan is never replanned on the way: the
    claims keep its order however late the robot runs (a replan would make a new order against robots already
    late on the old one).

    A robot never sets off on a stretch more than EARLY_S before its planned time: the plan is slower than the
    robot (PLANNED_SPEED), and one running ahead of it would meet robots planned to have left by then there. A
    nav stack drives at a pace of its own, which later plans are timed at (known_pace; until it is seen, the
    robot's speed limit: a stack slower than that is late, which the order allows for).
    A nav stack that gives up on a corner of the route (a goal its footprint cannot reach beside
    an obstacle) goes on to the next one; giving up on the goal itself ends the step. gone_round: the robots
    this trip went round (traffic.wait_for asks one that still stands in the way to make way)."""
    robot, goal, planned = session.robot, path[-1][:2], path[0][2]
    legs = stretches(path)
    due = planned  # when the next stretch is planned to begin
    for i, (x, y, t, hold) in enumerate(legs):
        begins = due
        await blocking.call(live.path, robot, [(round(p[0], 2), round(p[1], 2)) for p in legs[i:]], None)
        early = time.time() < due - tune.EARLY_S
        if hold or early:  # a planned wait, or early: keep to the plan's times
            await _hold(session, t if hold else due - tune.EARLY_S)
        due = t
        if hold:
            continue
        pose = await session.pose()
        ahead = [tuple(p[:2]) for p in legs[i:]]
        await traffic.wait_for(session, pose[:2], (x, y), (begins, t), ahead, gone_round)
        last = i == len(legs) - 1
        target = tuple(goal) if last else (x, y)
        distance = math.dist(pose[:2], target)
        if nav:
            limit = travel_time(distance * 1.5, math.pi, pace.stack_limits)
            sent = time.monotonic()
            try:
                await navigate(session, *target, limit, stall_s=tune.NAV_STALL_S)
            except Aborted:
                if last:
                    raise
                log.info(
                    "traffic: %s's nav stack gave up on a corner of its route, %s: on to the next",
                    robot.name,
                    target,
                )
                continue
            await _note_pace(session, distance, time.monotonic() - sent)
        else:
            tolerance = motion.TOLERANCE if last else _tolerance(pose[:2], legs, i)
            controller = motion.GoToGoal(target, pace.limits, tolerance)
            await drive(
                session,
                controller,
                travel_time(distance, math.pi, pace.limits),
                stall_s=STALL_S,
                goal=target,
            )


def _tolerance(here, legs, i: int) -> float:
    """How near the robot must come to the end of leg i before it heads for the next: WAYPOINT_TOLERANCE where
    the route goes on straight, CORNER_TOLERANCE where it turns. A plan's corners are where it goes round
    something (a shelf, a robot standing) as near as the robot's size allows: a corner cut by 0.2 m grazes it
    (TurtleBots stalled against shelf corners so)."""
    point, after = legs[i][:2], legs[i + 1][:2]
    before = legs[i - 1][:2] if i else here
    heading_in = math.atan2(point[1] - before[1], point[0] - before[0])
    heading_out = math.atan2(after[1] - point[1], after[0] - point[0])
    turn = abs(math.remainder(heading_out - heading_in, math.tau))
    return tune.CORNER_TOLERANCE if turn > tune.CORNER_TURN else tune.WAYPOINT_TOLERANCE


async def _note_pace(session: Session, distance: float, elapsed: float) -> None:
    """Learn the nav stack's pace from a stretch it drove (turns and ramps included): later plans are timed
    by it. The stack chooses its own speed, which the portal can only observe."""
    if distance < tune.PACE_MIN_M or elapsed <= 0:
        return
    await blocking.call(state.note_pace, session.robot.pk, distance / elapsed / session.link.clock.rate)


async def _hold(session: Session, until: float) -> None:
    """A wait in the plan: stay until its time (another robot passes first), at most HOLD_S beyond now."""
    deadline = min(until, time.time() + tune.HOLD_S)
    await session.link.halt()
    while time.time() < deadline:
        session.check()
        await session.pose()
