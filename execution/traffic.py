"""Traffic for the robots the portal moves: every motion reserved in space and time, claimed as it is driven.

The algorithms are plain (fleetcore.traffic); this module keeps their state in Redis, where every worker sees it:

1. Reserve (plan). When a robot sets off, its route is planned by space-time A* on safe intervals against the
   paths the other robots have reserved, the cells they hold now and the robots standing: every robot not
   under a plan (parked, or about to set off and not planned yet) stands for good where it is, as far as a
   plan knows, so no plan ever passes where another robot still stands. Its own timed path is then reserved
   under its id, until its step ends. First come, first reserved (prioritized planning), one plan at a time
   across the fleet: a newcomer waits or detours, robots under way are never replanned by it. A plan heeds
   the reservations all the way to its goal (no window, so nothing of it is blind to the others); where no
   such plan exists the robot stands and plans again (PLAN_AGAIN_S), never driving a plan blind to them.
   Plans and reservations keep SPACING_M more on each side than the claims ask, so robots a plan has pass
   side by side still get their claims when off their plans' lines. Plans are timed at the robot's real pace
   (its clock's rate; a nav stack's pace as seen), and a robot keeps to its plan's times: it never sets off
   on a stretch well before the plan says.
2. Claim (drive). Before each stretch of its route (at most LEG_M) the robot claims the room its footprint
   sweeps there. A claim is refused while another robot holds some of that room or stands in it; the robot
   then waits where it is and says for whom ("waiting for robot3"). Timing never has to be exact: a robot late
   or early against its reservation is held back by the claims, so no two robots are ever given the same room.
   A claim also keeps the plans' order (fleetcore.traffic.first_to_pass): a robot waits where another robot's
   plan has it first (within ORDER_ZONE more than both reaches) and that one has not got past yet, however
   late it is, with no exception, so robots on plans free of conflicts never wait on each other in a cycle:
   an action dependency graph (Hoenig et al. 2019). It holds only with all of 1. together: plans that heed
   everything to the goal, robots not yet planned standing for good, no replan on the way (runs bl to bq).
   A claim is checked and written in one Redis transaction (WATCH on the claims: optimistic, no lock to wait
   for or to lapse), so two robots claiming at the same moment never both get the same room.
3. Deadlock. Waiting robots note whom they wait for; a cycle of waits (fleetcore.traffic.wait_cycle) is broken
   by one of its robots (the one that gave way least often, then the highest id), which drops its claim ahead
   and replans around the robots of the cycle.
   A robot waiting on one that is parked (not under traffic) goes around it after REROUTE_AFTER_S.
4. Making way. An idle robot parked where another finds no way past it, or only a long one (_detour), is
   asked to make way (ask_to_make_way: an instruction of its own, as any person's would be checked); its
   make_way step moves it off the other's route (aside), waits for it to pass (until_passed) and comes back.

Robots with their own navigation stack take the same route as goals, one stretch at a time, each claimed
first: their goals never conflict with the reservations (execution.steps.navigate).
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import logging
import math
import time

from redis.exceptions import WatchError

import live
from execution import coordination, route, spots
from execution.models import Execution
from execution.steps import STALL_S, Aborted, Session, StepFailed, drive, navigate, travel_time
from fleetcore import motion
from fleetcore import traffic as plain
from robots import poses as pose_store
from robots.models import Robot

log = logging.getLogger(__name__)

LEG_M = 1.2  # m: the longest stretch claimed at once
RESERVE_MARGIN = 0.05  # m added to a robot's reach radius in reservations and claims
CLAIM_MARGIN = 0.05  # m more kept between two robots' room when claiming (2 x 0.05 + 0.05 < spots' margin)
APPROACH_SLACK = 0.03  # m a robot already too close may come nearer (a route planned on cells wobbles)
PLAN_MARGIN = 0.1  # m more again when planning round robots that stand (robots stop up to 0.2 m off a point)
CLAIM_TTL_S = 30.0  # a claim its robot no longer renews (a dead worker) lapses after this
RENEW_BEFORE_S = 20.0  # a waiting robot renews its claim once less than this is left of it
CLAIM_LIMIT_S = 10.0  # s of claims lost to others' writes (WATCH) before a claim gives up
SPACING_M = 0.1  # m more on each side in plans and reservations than claims ask (room to be off the line)
ORDER_ZONE = 0.15  # m more than both reaches within which two plans' passages are ordered (< 2 x SPACING_M)
HORIZON_S = 900.0  # s: plans heed the others' reservations all the way (no window)
PLAN_AGAIN_S = 2.0  # s a robot with no plan clear of the others stands before it plans again
SETTLE_M = 0.05  # m from its goal a robot stopped at a free spot next to it (a robot stood there)...
SETTLE_TRIES = 2  # ... plans again for the goal, this many times at most (the other may have left)
HOLD_S = 4.0  # s the cells another robot holds now are reserved for, in a newcomer's plan
WAIT_LIMIT_S = 120.0  # s a robot waits for cells before its step fails
REROUTE_AFTER_S = 4.0  # s waiting for a robot that is not under way before going around it
BUSY_WAIT_S = 20.0  # s waiting for a robot busy with an instruction (it may set off) before going around it
BUSY = ("running", "queued")
MAX_REROUTES = 4  # reroutes of one trip (deadlocks broken, robots standing gone round) before it fails
BACK_OFF_M = 0.4  # m a robot breaking a deadlock drives away from the others first (_back_off)
TURN_WAIT_S = 30.0  # s a robot waits for its turn to plan (robots sent together are planned one by one)
TURN_TTL_MS = 10_000  # a turn its planner no longer holds (a dead worker) lapses after this
TURN_POLL_S = 0.05
PROGRESS_EVERY_S = 0.1  # s between a planning robot's checks of its stop flag (_now_and_then)
MAX_REPLANS = 80  # plans of one trip: reroutes, and tries while no plan is clear of the others
REST_M = 0.002  # m between two odometry poses of a robot at rest
REST_LIMIT_S = 2.0  # s a robot told to stop may take to come to rest
WAIT_POLL_S = 0.2  # s between a waiting robot's tries
TELL_WAIT_S = 10.0  # s between a waiting robot's log lines (whom it waits for, and what that one does)
NOTE_WAIT_S = 0.6  # s between a waiting robot's notes of whom it waits for (and its deadlock checks)
WAYPOINT_TOLERANCE = 0.2  # m: a corner of the route needs no precision, only the goal does...
CORNER_TOLERANCE = 0.05  # m: ... but a corner (a turn sharper than CORNER_TURN) does (_tolerance)
CORNER_TURN = 0.35  # rad: a turn of the route sharper than this is a corner
NAV_STALL_S = 15.0  # s a nav stack may spend on its own recoveries without progress (move_base's take ~10 s)
MAP_POINTS = 60  # points at most of a reserved route kept for the map (routes())
NAV_PACE_GUESS = 0.5  # of a nav stack's top speed (at most 0.22 m/s): its stretches are given time at it
PACE_MIN_M = 0.3  # m: a nav stretch shorter than this says little of the stack's pace
PACE_WEIGHT = 0.5  # of a new measure of a nav stack's pace against what was known
EARLY_S = 1.0  # s a robot may set off on a stretch before the time its plan gives
SLOW_PLAN_MPS = 0.35  # m per s of wall time a fast robot is planned at when its own pace finds no plan
DETOUR_FACTOR = 1.5  # a way round robots parked in the way longer than this times the way through them...
DETOUR_M = 4.0  # ... plus this many metres (or none at all): the parked ones are asked to make way
MAKE_WAY_HOLD_S = 10.0  # s a robot asked to make way is taken to need to leave (claims hold it after)
MAKE_WAY_TTL_S = 240.0  # s a request to make way lasts (made way and back; refused: not asked again)
MAKE_WAY_WAIT_S = 120.0  # s a robot that made way waits for the other to pass before it goes back
MAKE_WAY_POLL_S = 0.5
ASIDE_STEP = 0.25  # m between the rings (and the points on them) searched for a spot off another's way
END_M = 1.0  # m from its start and its goal a plan may pass where the robot has room to pass but not to turn
ASIDE_SEARCH_M = 6.0  # m from where it stands a robot making way looks for that spot
PAD_GROWTH = 0.02  # s of a reservation's slack per second ahead (pad)
PLANNED_SPEED = 0.8  # of the commanded speed: turns on the spot and ramps make robots slower than their top


class Reroute(Exception):
    """Replan from here, around these robots (ids), which stand in the way."""

    def __init__(self, around: set[int]) -> None:
        super().__init__(around)
        self.around = around


def _key(name: str) -> str:
    return coordination.key("traffic", name)


def reach(robot: Robot) -> float:
    """The radius a robot takes in traffic: the farthest corner of its footprint from its centre (as goal spots
    count it), plus a margin."""
    return spots.radius_of(robot) + RESERVE_MARGIN


def _hash(redis, name: str) -> dict[int, dict]:
    """A traffic hash's entries by robot id, without the lapsed ones."""
    return _live(redis.hgetall(_key(name)))


def _live(raw_entries: dict) -> dict[int, dict]:
    now, out = time.time(), {}
    for field, raw in raw_entries.items():
        entry = json.loads(raw)
        if entry.get("expires", math.inf) > now:
            out[int(field)] = entry
    return out


def _put(redis, name: str, robot_id: int, entry: dict) -> None:
    redis.hset(_key(name), str(robot_id), json.dumps(entry, separators=(",", ":")))


def standing(redis, exclude: set[int]) -> list[tuple[plain.Capsule, float]]:
    """Robots not under traffic control, as discs standing since ever: their live pose, else where they parked,
    else their start pose. As far as the table knows, these stand where they are for good."""
    others = {
        r.pk: r for r in Robot.objects.exclude(pk__in=list(exclude)).only("pk", "footprint", "start_pose")
    }
    live_poses = pose_store.last_poses(list(others))
    parked = _hash(redis, "parked")
    out = []
    for pk, robot in others.items():
        pose = live_poses.get(pk) or parked.get(pk) or _start(robot)
        if pose is not None:
            point = (float(pose["x"]), float(pose["y"]))
            out.append((plain.Capsule(point, point, reach(robot), str(pk)), -math.inf))
    return out


def _start(robot: Robot) -> dict | None:
    pose = robot.start_pose
    return {"x": pose[0], "y": pose[1]} if pose and len(pose) >= 2 else None


def _capsule(pk: int, entry: dict) -> plain.Capsule:
    return plain.Capsule(tuple(entry["a"]), tuple(entry["b"]), entry["r"], str(pk))


def obstacles(redis, robot_id: int, now: float, around: set[int] = frozenset()):
    """What a newcomer must keep clear of: the paths others reserved and the stretches they hold now (in the
    table); where those robots will stand once arrived, and the robots standing (exact discs, from when).
    Robots in `around` count as standing where they hold room now, for good (a reroute goes round them)."""
    table, still = plain.ReservationTable(), []
    plans, claims = _hash(redis, "plans"), _hash(redis, "claims")
    for pk, entry in plans.items():
        if pk == robot_id or pk in around:
            continue
        for c, r, t0, t1 in entry["cells"]:
            if t1 > now - 1.0:  # what it has driven past holds nobody up
                table.reserve(str(pk), [(c, r)], t0, t1)
        goal = tuple(entry["goal"])
        still.append((plain.Capsule(goal, goal, entry["r"], str(pk)), entry["at"]))
    for pk, entry in claims.items():
        if pk == robot_id:
            continue
        held = _capsule(pk, entry)
        if pk in around or pk not in plans:  # not planned yet: where it stands, for good, as far as we know
            still.append((held, -math.inf))
        else:
            table.reserve(
                str(pk), plain.swept_cells(held.a, held.b, held.r + SPACING_M), now - 1.0, now + HOLD_S
            )
    still.extend(standing(redis, {robot_id, *claims, *plans}))
    return table, still


def busy_ids() -> set[int]:
    """Robots with an execution running or queued: one standing now is about to move, not parked."""
    return set(Execution.objects.filter(status__in=BUSY).values_list("robot_id", flat=True))


def is_busy(robot_id: int) -> bool:
    """Whether one robot is busy (busy_ids), asked of it alone."""
    return Execution.objects.filter(robot_id=robot_id, status__in=BUSY).exists()


def pad(t0: float):
    """Timing slack of a reservation made at t0: half a second, plus PAD_GROWTH of the time ahead. Small: the
    claims keep the plans' order however late or early a robot is (first_to_pass); slack only spaces the
    plans. (A tenth, before the order was kept, made reservations 30 s ahead 7 s wide, and crowds' searches
    failed for lack of room: 33 failed searches in run aw.)"""
    return lambda t: 0.5 + PAD_GROWTH * max(0.0, t - t0)


def plan(
    robot: Robot,
    start,
    goal,
    speed: float,
    around: set[int] = frozenset(),
    progress=None,
    settled: bool = False,
    may_ask: bool = False,
) -> list[tuple]:
    """Plan and reserve the robot's timed path [(x, y, t), ...] from start to goal (wall-clock t), in its
    turn (planning_turn): each plan sees the ones reserved before it. Claims are never held up by a plan.
    settled: the goal is the spot an earlier plan of this trip chose; it moves only if a robot would touch it.
    may_ask: robots parked in the way, idle, may be asked to make way (the plan then passes where they stand
    once they have moved; ask_to_make_way sends them the instruction after the turn)."""
    asked = time.monotonic()
    progress = _now_and_then(progress)
    with planning_turn(robot, progress):
        began = time.monotonic()
        path = _plan(robot, start, goal, speed, around, progress, settled, may_ask)
    done = time.monotonic()
    if may_ask:
        ask_to_make_way(robot)
    if path is not None:
        log.info(
            "traffic: %s planned in %.2f s after %.2f s waiting for its turn; arrives in %.0f s",
            robot.name,
            done - began,
            began - asked,
            path[-1][2] - path[0][2],
        )
    return path


def _now_and_then(progress):
    """progress (the step's check: a Redis read of its stop flag) called at most every PROGRESS_EVERY_S: a
    search calls it every few hundred steps, a robot waiting for its turn every poll; 32 robots doing so
    spent a seventh of their planning time on it and kept Redis busy."""
    if progress is None:
        return None
    last = -math.inf

    def call() -> None:
        nonlocal last
        if time.monotonic() - last >= PROGRESS_EVERY_S:
            last = time.monotonic()
            progress()

    return call


@contextlib.contextmanager
def planning_turn(robot: Robot, progress=None):
    """One plan at a time across the fleet (prioritized planning: robots sent together are planned in turn,
    each against the paths reserved before it, instead of all against the same snapshot). A turn that does not
    come within TURN_WAIT_S is not waited for (the claims still keep robots apart); a planner that dies lets
    its turn lapse after TURN_TTL_MS."""
    redis, token = coordination.connection(), coordination.new_token()
    deadline = time.monotonic() + TURN_WAIT_S
    held = False
    while not (held := bool(redis.set(_key("turn"), token, nx=True, px=TURN_TTL_MS))):
        if time.monotonic() > deadline:
            log.info("traffic: %s plans without waiting longer for its turn", robot.name)
            break
        if progress is not None:
            progress()
        time.sleep(TURN_POLL_S)
    try:
        yield
    finally:
        if held:
            redis.eval(coordination.RELEASE, 1, _key("turn"), token)


def _plan(
    robot: Robot, start, goal, speed: float, around: set[int], progress, settled: bool, may_ask: bool
) -> list[tuple] | None:
    """The plan itself: read the table, search (searches(): less demanding each time one finds nothing),
    reserve; None when no search finds a plan clear of the others (nothing is reserved). Without a map, the
    straight line is reserved; to a goal off the map's free ground (by a wall, for the map inflated by the
    robot's size), the map route, as it is (the claims keep it apart). A plan that finds no way past
    idle robots parked on the map route, or only a long way round them (_detour), passes where they stand
    once they have made way, when they may be asked."""
    planner, passable = trip_ground(robot, start, goal)
    radius = reach(robot)
    now = time.time()
    path, heeds = None, 0.0  # heeds: how far ahead the plan heeded the others' reservations
    if planner is not None:
        redis = coordination.connection()
        table, still = obstacles(redis, robot.pk, now, around)  # a snapshot: no lock
        grow = CLAIM_MARGIN + PLAN_MARGIN  # plan wider than claims need: a robot off its line still gets them
        exact, still = still, [(_grown(c, grow), since) for c, since in still]
        goal = free_goal(robot, goal, radius, exact if settled else still, planner, start)
        still = _stoppable(goal, radius, still, exact)
        if not planner.free(*planner.to_cell(*goal)):  # the search takes the goal's point to be free ground
            log.info(
                "traffic: %s's goal %s is off the free ground: it drives the map route", robot.name, goal
            )
            path = _timed([tuple(start), *route.route(robot, tuple(start), tuple(goal))], speed, now)
            _reserve(redis, robot, path, radius, now, 0.0)
            return path
        path, heeds = _search(robot, passable, start, goal, speed, now, table, still, progress)
        through = _detour(path, start, goal, planner) if may_ask else None
        idle = _idle_in_the_way(redis, robot, through, exact) if through else {}
        if idle:  # the same search with them gone from where they stand after MAKE_WAY_HOLD_S
            for pk, disc in idle.items():
                cells = plain.footprint_cells(disc.a, disc.r)
                table.reserve(str(pk), cells, now - 1.0, now + MAKE_WAY_HOLD_S)
            rest = [(c, since) for c, since in still if int(c.label) not in idle]
            passing, passing_heeds = _search(robot, passable, start, goal, speed, now, table, rest, progress)
            asked = {pk: disc for pk, disc in idle.items() if passing and _passes(passing, disc, radius)}
            if asked:  # (a plan that went round them all the same asks nobody)
                path, heeds = passing, passing_heeds
                _request_way(redis, robot, asked, through)
    if planner is None:  # no map: the straight line, timed, which the claims keep apart
        path, heeds = _timed([tuple(start), tuple(goal)], speed, now), 0.0
    if path is None:
        log.info("traffic: %s has no conflict-free plan to %s; it stands and plans again", robot.name, goal)
        return None
    _reserve(coordination.connection(), robot, path, radius, now, heeds)  # one transaction, its own entries
    return path


def _stoppable(goal, radius: float, still, exact):
    """The robots standing as the search heeds them (`still`: with the planning margins), but with only the
    claims' margin (`exact`, in the same order, grown by CLAIM_MARGIN) those the goal lies within the planning
    margins of: a goal kept from an earlier plan of the trip (free_goal: moved only if a claim would be
    refused there) where the search could never stop: each of its searches spent its 60,000 states waiting
    for a way to stop there, and the robot drove the map route, blind to the reservations (the replans of a
    trip, most robots' plans, are settled). Not at their exact size: a plan round one 0.04 m nearer than
    the claims allow was refused its stretch there, rerouted round it and replanned the same, four times,
    and its step failed (run av)."""
    return [
        (_grown(near, CLAIM_MARGIN) if plain.segment_distance(goal, goal, grown.a, grown.b) < grown.r + radius
         else grown, since)
        for (grown, since), (near, _) in zip(still, exact, strict=True)
    ]  # fmt: skip


def _grown(capsule: plain.Capsule, margin: float) -> plain.Capsule:
    return plain.Capsule(capsule.a, capsule.b, capsule.r + margin, capsule.label)


def trip_ground(robot: Robot, start, goal):
    """(planner, passable) of a trip; (None, None) without a map. The planner is the map inflated by half the
    robot's narrow side (the goal's ground, the map route); its plan goes where it has room to turn on the
    spot (half its diagonal: it turns where two legs meet; planned by half its width, Huskies turning by a
    rack's corner or a wall stalled: runs ah, ai), and within END_M of its start and its goal where it has
    room to pass (a goal or a start by a wall or a shelf: when that sent a whole trip onto the narrow map, a
    Husky stalled turning mid-aisle 0.5 m from a rack, tried as a user)."""
    passing = route.planner_for(robot)
    if passing is None:
        return None, None
    turning, narrow = _passable(route.planner_for(robot, turning=True)), _passable(passing)
    ends = (tuple(start[:2]), tuple(goal[:2]))

    def passable(cell) -> bool:
        if turning(cell):
            return True
        point = plain.center_of(cell)
        return narrow(cell) and any(math.dist(point, end) < END_M for end in ends)

    return passing, passable


def _search(robot: Robot, passable, start, goal, speed: float, now: float, table, still, progress):
    """The first plan of searches() that finds one on these cells (passable), and how far ahead it heeded the
    others' reservations (all the way); (None, 0.0) when none finds one."""
    radius = reach(robot)
    for pace in searches(speed):
        search = plain.SpaceTimeSearch(
            passable, radius, pace, pad(now), horizon_s=HORIZON_S, spacing=SPACING_M
        )
        path = search.plan(tuple(start), tuple(goal), now, table, str(robot.pk), still, progress)
        if path is not None:
            return path, math.inf
        log.info(
            "traffic: %s found no plan to %s at %.2f m/s (%d states)", robot.name, goal, pace, search.expanded
        )
    return None, 0.0


def _length(points) -> float:
    return sum(math.dist(a[:2], b[:2]) for a, b in itertools.pairwise(points))


def _detour(path, start, goal, planner) -> list[tuple[float, float]] | None:
    """The map route from start to goal (robots ignored) when the plan found is no way, or a detour from it
    of more than DETOUR_FACTOR times plus DETOUR_M; else None. The map route is planned only for a plan
    that is long against the straight line (a tenth of a second on the warehouse's map)."""
    if path is not None and _length(path) <= DETOUR_FACTOR * math.dist(start, goal) + DETOUR_M:
        return None
    through = planner.plan(tuple(start), tuple(goal))
    if not through or (path is not None and _length(path) <= DETOUR_FACTOR * _length(through) + DETOUR_M):
        return None
    return [tuple(start), *through]


def _idle_in_the_way(redis, robot: Robot, through, exact) -> dict[int, plain.Capsule]:
    """The robots standing on the map route (within reach of it) that are idle, not asked already, not
    refused lately and not made way for this robot lately: {id: where they stand}. Robots under traffic,
    busy ones (about to set off: plans go round them, but they are not asked) and others' goals are not
    idle."""
    asked = {pk for pk, e in _hash(redis, "makeway").items() if not e.get("done") or e["for"] == robot.pk}
    under = set(_hash(redis, "plans")) | set(_hash(redis, "claims")) | asked | busy_ids()
    return {
        int(disc.label): disc
        for disc, since in exact
        if since == -math.inf and int(disc.label) not in under and _passes(through, disc, reach(robot))
    }


def _passes(path, disc: plain.Capsule, radius: float) -> bool:
    """Whether a path comes within reach of where a robot stands."""
    legs = itertools.pairwise(p[:2] for p in path)
    return any(plain.segment_distance(disc.a, disc.a, a, b) < radius + disc.r + CLAIM_MARGIN for a, b in legs)


def _request_way(redis, robot: Robot, idle: dict, through) -> None:
    """Ask, in the traffic table, the idle robots in the way to make way: sent after the turn
    (ask_to_make_way), read by their make_way step (way_request)."""
    points = [[round(p[0], 2), round(p[1], 2)] for p in through]
    for pk in idle:
        entry = {"for": robot.pk, "r": reach(robot), "route": points, "sent": False}
        _put(redis, "makeway", pk, {**entry, "expires": time.time() + MAKE_WAY_TTL_S})
    log.info("traffic: %s asks %s to make way", robot.name, sorted(idle))


def ask_to_make_way(robot: Robot) -> None:
    """Send each robot this one asked to make way (_request_way) a make_way instruction, as the person whose
    instruction this robot runs: the robot's lease, schedule and state are checked as for any instruction.
    A refusal is kept in the table (that robot is not asked again by anyone for MAKE_WAY_TTL_S) and said."""
    from execution.instructions import submit  # the instruction layer sits on top of the route handlers

    redis = coordination.connection()
    asked = {pk: e for pk, e in _hash(redis, "makeway").items() if e.get("for") == robot.pk and not e["sent"]}
    if not asked:
        return
    running = Execution.objects.filter(robot=robot, status="running").select_related("instruction__user")
    user = next((execution.instruction.user for execution in running), None)
    names = dict(Robot.objects.filter(pk__in=list(asked)).values_list("pk", "name"))
    for pk, entry in asked.items():
        step = {"action": "make_way", "robots": [names[pk]]}
        parse = {"type": "I", "valid": True, "needs_user": False, "steps": [step]}
        text = f"{names[pk]} make way for {robot.name}"
        _put(redis, "makeway", pk, {**entry, "sent": True, "refused": ""})  # before its step may read it
        sent = submit(text, user, source="traffic", parse=parse)
        if sent.status == "refused":
            _put(redis, "makeway", pk, {**entry, "sent": True, "refused": sent.outcome})
            log.info("traffic: %s cannot make way for %s: %s", names[pk], robot.name, sent.outcome)


def way_request(robot: Robot) -> dict | None:
    """What the robot is to make way for: {"for": id, "r": its reach, "route": [[x, y], ...]}; asked by a plan
    (_request_way), or, for a person who told it to, the first robot waiting for it (along its reserved
    path). None when nobody needs its room."""
    redis = coordination.connection()
    entry = _hash(redis, "makeway").get(robot.pk)
    if entry is not None and not entry.get("done") and not entry.get("refused"):
        return entry
    waiting = [pk for pk, wait in _hash(redis, "waits").items() if wait.get("for") == robot.pk]
    plans = _hash(redis, "plans")
    for pk in waiting:
        if pk in plans:
            return {"for": pk, "r": plans[pk]["r"], "route": plans[pk]["path"]}
    return None


def aside(robot: Robot, here, request: dict) -> tuple[float, float] | None:
    """The free spot nearest to `here` where the robot stands clear of the route it makes way for (by both
    robots' reach and the planning margins) and of the robots standing and the goals reserved; None when
    there is none within ASIDE_SEARCH_M."""
    planner = route.planner_for(robot, turning=True)  # it turns there, to come back
    radius, route_points = reach(robot), [tuple(p) for p in request["route"]]
    clear = request["r"] + radius + CLAIM_MARGIN + PLAN_MARGIN
    legs = list(itertools.pairwise(route_points)) or [(route_points[0], route_points[0])]

    def is_free(x: float, y: float) -> bool:
        if planner is not None and not planner.free(*planner.to_cell(x, y)):
            return False
        return all(plain.segment_distance((x, y), (x, y), a, b) >= clear for a, b in legs)

    _, still = obstacles(coordination.connection(), robot.pk, time.time(), {request["for"]})
    discs = [plain.Disc(c.a[0], c.a[1], c.r, c.label) for c, _ in still if int(c.label) != request["for"]]
    return plain.free_spot(
        tuple(here), radius, discs, is_free, prefer=tuple(here), step=ASIDE_STEP, search_m=ASIDE_SEARCH_M,
        margin=CLAIM_MARGIN + PLAN_MARGIN,
    )  # fmt: skip


def until_passed(session: Session, request: dict, home) -> float:
    """Wait, standing aside, until the robot made way for has passed `home` (it has a plan, none of whose
    cells near `home` lies ahead of where its claim starts, in the plan's order, and its claim is clear of
    it; a robot waiting to plan again has not passed), is done with its instruction or waits for this
    one where it stands aside; at most MAKE_WAY_WAIT_S. Returns the seconds waited. (Judged by the clock, a
    robot held up by the claims had "passed" as soon as its plan's times had: robots came back after 0 s
    in runs ad and ae.)"""
    redis, other, started = coordination.connection(), request["for"], time.monotonic()
    near = reach(session.robot) + plain.TRAFFIC_CELL
    clear = request["r"] + reach(session.robot) + CLAIM_MARGIN
    session.link.halt()
    while time.monotonic() - started < MAKE_WAY_WAIT_S:
        plans, claims, now = _hash(redis, "plans"), _hash(redis, "claims"), time.time()
        if not is_busy(other):
            break  # done with its instruction
        if _hash(redis, "waits").get(other, {}).get("for") == session.robot.pk:
            break  # its way now goes through the spot aside (run af: each waited for the other for 120 s)
        if other in plans:  # (between two plans, or two tries of a stalled trip, it has not passed: run w)
            held, cells = claims.get(other), plans[other]["cells"]
            at = _plan_time_at(cells, held["a"]) if held else None
            at = now if at is None else at  # where the plan has it now (a robot late on it: run ae)
            ahead = any(
                t0 > at and math.dist(plain.center_of((col, row)), home) < near for col, row, t0, _ in cells
            )
            if not ahead and (
                held is None or plain.segment_distance(home, home, held["a"], held["b"]) > clear
            ):
                break
        deadline = time.monotonic() + MAKE_WAY_POLL_S
        while time.monotonic() < deadline:
            session.check()
            session.pose()
    return time.monotonic() - started


def _plan_time_at(cells, point) -> float | None:
    """When a plan's reserved cells first have the robot at `point` (its cell or one next to it); None when
    the plan does not pass there."""
    times = [
        t0 for col, row, t0, _ in cells if math.dist(plain.center_of((col, row)), point) < plain.TRAFFIC_CELL
    ]
    return min(times, default=None)


def made_way(robot: Robot, failed: str = "") -> None:
    """The robot is back: its request is done, and stays so until it lapses (the robot that asked does not ask
    it again on a later plan of its trip; another robot may). Or it could not make way: the request stays,
    refused (the robot that asked goes round it; nobody asks it again for a while)."""
    redis = coordination.connection()
    entry = _hash(redis, "makeway").get(robot.pk)
    if entry is None:
        return
    outcome = {"refused": failed} if failed else {"done": True}
    _put(redis, "makeway", robot.pk, {**entry, "sent": True, "refused": "", **outcome})


def searches(speed: float) -> list[float]:
    """The paces of the searches tried in turn until one finds a plan: the robot's; a fast robot's again at
    SLOW_PLAN_MPS (its moves are fewer ticks of search, and it finds plans a fast one does not). Each heeds
    the reservations all the way to the goal: a plan blind to them beyond a window (replanned before the
    window ran out, against robots late on their plans) or as a last resort let the order go round."""
    return [speed, SLOW_PLAN_MPS] if speed > SLOW_PLAN_MPS * 1.2 else [speed]


def free_goal(robot: Robot, goal, radius: float, still, planner, start) -> tuple[float, float]:
    """The goal, or the nearest free spot to it when a robot stands too close (one that stopped a little
    short of its own spot, say): where this robot can stop clear of everyone."""
    discs = [plain.Disc(c.a[0], c.a[1], c.r, c.label) for c, _ in still]
    if plain.clear_of(tuple(goal), radius, discs, 0.05) is None:
        return tuple(goal)
    is_free = lambda x, y: planner.free(*planner.to_cell(x, y))  # noqa: E731
    spot = plain.free_spot(
        tuple(goal), radius, discs, is_free, prefer=tuple(start), margin=CLAIM_MARGIN + 0.01
    )
    if spot is None:
        return tuple(goal)
    log.info(
        "traffic: %s stops at %s, %.2f m from its goal %s (taken)",
        robot.name,
        spot,
        math.dist(spot, goal),
        goal,
    )
    return spot


@functools.lru_cache(maxsize=16)
def _passable(planner):
    """Whether the robot may stand anywhere in a traffic cell: the planner's map is free at each of its
    corners (a cell free at its centre only lets a path between two such cells, or a straightened leg
    through them, clip a shelf's corner by up to 0.14 m, where the map keeps 0.05 m: TurtleBots stalled so).
    One per planner (robot size and map version), its answers kept."""
    known: dict = {}
    half = plain.TRAFFIC_CELL / 2 - 1e-6

    def passable(cell) -> bool:
        if cell not in known:
            x, y = plain.center_of(cell)
            known[cell] = all(
                planner.free(*planner.to_cell(x + dx, y + dy)) for dx in (-half, half) for dy in (-half, half)
            )
        return known[cell]

    return passable


def _timed(points, speed: float, t0: float) -> list[tuple]:
    out, t = [(*points[0], t0)], t0
    for a, b in itertools.pairwise(points):
        t += math.dist(a, b) / speed
        out.append((*b, t))
    return out


def _reserve(redis, robot: Robot, path: list[tuple], radius: float, now: float, heeds: float) -> None:
    """Write the robot's plan: its reserved cells (for the plans after it), its timed path up to where it
    heeded the others' reservations (`heeds` s ahead: the claims keep its order there, first_to_pass), and its
    route for the map."""
    table = plain.ReservationTable()
    table.reserve_path(str(robot.pk), path, radius + SPACING_M, pad(now))
    busy = table.intervals()  # merged per cell: a few intervals each, not one per stretch that touches it
    cells = [
        [c, r, round(t0, 2), round(t1, 2)]
        for (c, r), spans in busy.cells.items()
        for t0, t1 in zip(spans.starts, spans.ends, strict=True)
    ]
    x, y, at = path[-1]
    entry = {"cells": cells, "goal": [x, y], "r": radius, "at": at, "expires": at + WAIT_LIMIT_S * 2}
    entry["path"] = [[round(p[0], 2), round(p[1], 2)] for p in path[:: max(1, len(path) // MAP_POINTS)]]
    entry["path"].append([round(x, 2), round(y, 2)])  # what a map that opens now draws (routes())
    timed = [[round(x, 3), round(y, 3), round(t, 2)] for x, y, t in path]  # its order, for the claims
    with redis.pipeline() as pipe:  # (one transaction: a claim never reads one plan's cells, another's order)
        _put(pipe, "plans", robot.pk, entry)
        order = {
            "path": timed,
            "r": radius,
            "until": round(now + min(heeds, 1e6), 2),
            "expires": entry["expires"],
        }
        _put(pipe, "timed", robot.pk, order)
        pipe.execute()


def routes(robot_ids) -> dict[int, dict]:
    """{robot id: {"path": [[x, y], ...], "waiting_for": robot id or None}} of the robots under traffic now,
    for a page that opens while they drive (live.path sends the changes after)."""
    redis, wanted = coordination.connection(), set(robot_ids)
    waits = {pk: entry.get("for") for pk, entry in _hash(redis, "waits").items() if pk in wanted}
    plans = {pk: entry.get("path", []) for pk, entry in _hash(redis, "plans").items() if pk in wanted}
    return {
        pk: {"path": plans.get(pk, []), "waiting_for": waits.get(pk)} for pk in plans.keys() | waits.keys()
    }


def claim(robot: Robot, start, end, progress=None, everyone=None, planned=None, why=None) -> int | None:
    """Claim the stretch from start to end for the robot (replacing its previous claim); the id of a robot in
    the way (holding room there, or standing there, or planned there before this one: first_to_pass), or None
    when the claim is the robot's.

    everyone: the robots standing (standing()), when the caller has them (a waiting robot reads them less
    often than it tries). planned: (t0, t1), the stretch's times in the robot's plan: the claim keeps the
    plans' order (a robot planned there first and not yet past goes first), and the robot's progress (t0) is
    written with it for the others to do the same. why: a list, given the reason a claim was refused ("room":
    the robot in the way holds or stands in the room; "order": it is planned there first)."""
    radius, redis = reach(robot), coordination.connection()
    if everyone is None:
        everyone = standing(redis, {robot.pk})  # the slow part (database), before the transaction
    deadline = time.monotonic() + CLAIM_LIMIT_S
    while True:
        with redis.pipeline() as pipe:
            try:
                pipe.watch(_key("claims"))
                return _claim(pipe, robot, start, end, radius, everyone, planned, why)
            except WatchError:  # another robot's claim was written between our read and our write: again
                if time.monotonic() > deadline:
                    raise StepFailed("the traffic table is too busy to claim a stretch; try again") from None
                if progress is not None:
                    progress()


def _claim(pipe, robot: Robot, start, end, radius: float, everyone, planned, why) -> int | None:
    """Within a WATCH on the claims: the robot in the way, or write the claim (and drop the robot's wait)."""
    held = {pk: e for pk, e in _live(pipe.hgetall(_key("claims"))).items() if pk != robot.pk}
    claims = {pk: _capsule(pk, e) for pk, e in held.items()}
    others = [*claims.values(), *(disc for disc, _ in everyone if int(disc.label) not in claims)]
    blocker = plain.first_in_the_way(tuple(start), tuple(end), radius, others, CLAIM_MARGIN, APPROACH_SLACK)
    if blocker is None and planned is not None and tuple(start) != tuple(end):
        others = _planned(pipe, held)
        blocker = plain.first_to_pass(tuple(start), tuple(end), *planned, radius, others, ORDER_ZONE)
    if blocker is not None:
        pipe.unwatch()
        if why is not None:
            why.append("room" if isinstance(blocker, plain.Capsule) else "order")
        return int(blocker.label if isinstance(blocker, plain.Capsule) else blocker)
    entry = {"a": list(start), "b": list(end), "r": radius, "expires": time.time() + CLAIM_TTL_S}
    if planned is not None:
        entry["t"] = planned[0]
    pipe.multi()
    pipe.hset(_key("claims"), str(robot.pk), json.dumps(entry, separators=(",", ":")))
    pipe.hdel(_key("waits"), str(robot.pk))
    pipe.execute()
    return None


def _planned(redis, held: dict[int, dict]) -> list[plain.Planned]:
    """The timed plans of the other robots under way (holding a claim: a plan whose robot's worker died
    lapses with its claim) that heeded the reservations, each with its progress (the planned time of the
    stretch it holds; its plan's start until it claims one) and the time up to which it heeded them."""
    out = []
    for pk, entry in _hash(redis, "timed").items():
        if pk in held and entry["until"] > entry["path"][0][2]:
            path = [tuple(p) for p in entry["path"]]
            progress = held[pk].get("t", path[0][2])
            out.append(plain.Planned(str(pk), path, entry["r"], progress, entry["until"]))
    return out


def _yet_to_pass(robot: Robot, spot) -> bool:
    """Whether another robot under way has yet to pass near where this one stands (by its plan, from where
    its claim begins): then this one does not plan again from there (the order would have that one first
    where it must pass this one), it stays where it is, and that one goes round it as round any robot
    parked (run br: a robot planning again for its goal, taken before, waited by the order for a Husky
    that waited for its room)."""
    redis = coordination.connection()
    claims, radius = _hash(redis, "claims"), reach(robot)
    for pk, entry in _hash(redis, "timed").items():
        if pk == robot.pk or pk not in claims:
            continue
        progress = claims[pk].get("t", entry["path"][0][2])
        near = radius + entry["r"] + ORDER_ZONE + CLAIM_MARGIN
        rest = [tuple(claims[pk]["a"]), *(tuple(p[:2]) for p in entry["path"] if p[2] >= progress)]
        if any(plain.segment_distance(spot, spot, p, q) < near for p, q in itertools.pairwise(rest)):
            return True
    return False


def _drop_plan(robot: Robot) -> None:
    """The robot has no plan now (none found): it stands, and the others plan round it and wait for nothing of
    its old way."""
    redis = coordination.connection()
    with redis.pipeline() as pipe:
        for name in ("plans", "timed"):
            pipe.hdel(_key(name), str(robot.pk))
        pipe.execute()


def release(robot: Robot, pose) -> None:
    """The step has ended: drop the robot's reservation, claim and wait; remember where it parked."""
    redis = coordination.connection()
    with redis.pipeline() as pipe:
        for name in ("plans", "timed", "claims", "waits", "breaks"):
            pipe.hdel(_key(name), str(robot.pk))
        if pose is not None:
            pipe.hset(_key("parked"), str(robot.pk), json.dumps({"x": pose[0], "y": pose[1]}))
        pipe.execute()
    if pose is not None:
        pose_store.store_pose(robot.pk, pose)
    live.path(robot, [], None)


def deadlocks() -> int:
    """Wait-for cycles found and broken so far (the bench reads it)."""
    return int(coordination.connection().get(_key("deadlocks")) or 0)


def wait_for(session: Session, start, end, planned=None) -> None:
    """Claim the stretch, waiting while another robot is in the way (or is planned there first: claim());
    raise Reroute to break a deadlock or to go around a robot that is not under way; StepFailed after
    WAIT_LIMIT_S. planned: the stretch's (t0, t1) in the robot's plan.

    A waiting robot holds only the room it stands in (others may pass behind it) and tries every WAIT_POLL_S;
    every NOTE_WAIT_S it reads the robots standing afresh, notes whom it waits for, keeps its claim alive and
    looks for a cycle of waits."""
    robot, redis = session.robot, coordination.connection()
    started = same_since = noted = told = time.monotonic()
    last, name, everyone, why = None, "", None, []
    while (blocker := claim(robot, start, end, session.check, everyone, planned, why)) is not None:
        now = time.monotonic()
        if blocker != last:
            if last is None:  # it waits where it comes to rest: it holds that room, not the stretch behind
                here = _at_rest(session)
                claim(robot, here, here, session.check, everyone, planned)
            same_since, last = now, blocker
            name = Robot.objects.filter(pk=blocker).values_list("name", flat=True).first() or f"#{blocker}"
            log.debug("traffic: %s waits for %s to go from %s to %s", robot.name, name, start, end)
            live.path(robot, None, name)
            noted = -math.inf
        if now - noted >= NOTE_WAIT_S:
            noted, everyone = now, standing(redis, {robot.pk})
            wanted = [[round(v, 2) for v in point[:2]] for point in (start, end)]
            entry = {"for": blocker, "why": why[-1], "to": wanted, "expires": time.time() + 2.0}
            _put(redis, "waits", robot.pk, entry)
            _renew(redis, robot.pk)
            _check_deadlock(redis, robot.pk)
            if now - same_since > REROUTE_AFTER_S and _parked(redis, blocker, now - same_since):
                log.info("traffic: %s goes round %s, which stands in its way", robot.name, name)
                raise Reroute({blocker})
        if now - told >= TELL_WAIT_S:
            told = now
            log.info(
                "traffic: %s has waited %.0f s for %s (%s)",
                robot.name,
                now - started,
                name,
                _doing(redis, blocker),
            )
        if now - started > WAIT_LIMIT_S:
            raise StepFailed(f"{robot.name}: waited {WAIT_LIMIT_S:.0f} s for {name} to make way")
        session.check()
        time.sleep(WAIT_POLL_S)
        session.pose()  # a robot waiting still reads where it is (and odometry that stops fails the step)
    if last is not None:
        live.path(robot, None, None)


def _doing(redis, robot_id: int) -> str:
    """What a robot in the way is doing, as the traffic tables say (for the log of a long wait)."""
    waits = _hash(redis, "waits")
    if robot_id in waits:
        return f"it waits for #{waits[robot_id].get('for')}"
    if robot_id in _hash(redis, "claims"):
        return "it holds room under way"
    return "it stands, not under traffic"


def _at_rest(session: Session) -> tuple[float, float]:
    """Stop the robot and read odometry until it has come to rest (or REST_LIMIT_S): where it stands."""
    session.link.halt()
    deadline = time.monotonic() + REST_LIMIT_S
    before = session.pose()
    while time.monotonic() < deadline:
        now = session.pose()
        if math.dist(before[:2], now[:2]) < REST_M:
            return now[:2]
        before = now
    return before[:2]


def _parked(redis, blocker: int, waited: float) -> bool:
    """Whether a robot in the way is parked (go round it), not one under way or about to be (wait for it)."""
    if blocker in _hash(redis, "claims"):
        return False
    request = _hash(redis, "makeway").get(blocker)
    if request is not None and request.get("sent") and not request.get("refused") and not request.get("done"):
        return False  # it was asked to make way (for this robot or another): it will
    return not is_busy(blocker) or waited > BUSY_WAIT_S


def _renew(redis, robot_id: int) -> None:
    """Keep the robot's claim (where it stands and what it holds) alive while it waits, once it is needed
    (each write of the claims makes the others' claims in flight try again)."""
    raw = redis.hget(_key("claims"), str(robot_id))
    if raw is None:
        return
    entry = json.loads(raw)
    if entry.get("expires", 0) - time.time() < RENEW_BEFORE_S:
        _put(redis, "claims", robot_id, {**entry, "expires": time.time() + CLAIM_TTL_S})


def _check_deadlock(redis, robot_id: int) -> None:
    """If this robot is in a cycle of waits and is the one to give way, it does: Reroute. The one to give way
    has given way least often on its trip, ties to the highest id: a robot whose reroutes did not get it out
    of the others' way is not asked again and again while they wait.

    Read and decided under a WATCH of the waits, and the breaker's wait dropped in the same transaction: two
    robots of one cycle checking at once both broke it (run r: the second read the first's count of breaks
    but still its wait), each backing off and counted as a deadlock."""
    with redis.pipeline() as pipe:
        try:
            pipe.watch(_key("waits"))
            entries = _hash(pipe, "waits")
            waits = {str(pk): str(entry["for"]) for pk, entry in entries.items()}
            cycle = plain.wait_cycle(waits, str(robot_id))
            if not cycle:
                return
            given = dict(zip(cycle, pipe.hmget(_key("breaks"), cycle), strict=True))
            if min(cycle, key=lambda pk: (int(given[pk] or 0), -int(pk))) != str(robot_id):
                return
            held = {pk: (e["a"], e["b"]) for pk, e in _hash(pipe, "claims").items() if str(pk) in cycle}
            pipe.multi()
            pipe.hdel(_key("waits"), str(robot_id))
            pipe.incr(_key("deadlocks"))
            pipe.hincrby(_key("breaks"), str(robot_id), 1)
            pipe.execute()
        except WatchError:  # a wait changed as we read: the next check (NOTE_WAIT_S on) reads it afresh
            return
    why = {  # what each waits for (room, or its turn: order) and the stretch it waits to drive
        pk: (entries[int(pk)].get("why"), entries[int(pk)].get("to")) for pk in cycle
    }
    log.info(
        "traffic: deadlock among robots %s broken by %s (room held: %s; waits: %s)",
        cycle,
        robot_id,
        held,
        why,
    )
    raise Reroute({int(pk) for pk in cycle} - {robot_id})


def stretches(path: list[tuple]) -> list[tuple]:
    """The route cut into stretches of at most LEG_M: [(x, y, t, hold)], hold True for a planned wait."""
    out = []
    for a, b in itertools.pairwise(path):
        if a[:2] == b[:2]:
            out.append((*b, True))
            continue
        n = max(1, math.ceil(math.dist(a[:2], b[:2]) / LEG_M))
        for i in range(1, n + 1):
            f = i / n
            out.append((a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f, False))
    return out


def travel(session: Session, goal, limits: motion.Limits, factor: float, nav: bool = False) -> str:
    """Drive (or, with its own nav stack, navigate) the robot to goal along a reserved route, stretch by
    stretch, each claimed first; replan around a deadlock or a robot standing in the way.

    Returns "" at the goal, or words on the free spot it stopped at when a robot stood on the goal."""
    robot = session.robot
    _measure_clock(session)
    around: set[int] = set()
    reroutes, settles, stuck_since = 0, 0, None
    here = session.pose()[:2]
    claim(robot, here, here, session.check)  # under traffic from now on: others wait for it, not go round it
    try:
        spot = tuple(goal)  # where it stops: the goal, or a free spot next to it (the first plan says)
        for replans in range(MAX_REPLANS):
            pose = session.pose()
            learned = known_pace(robot.pk) if nav else None
            pace = _pace(limits, factor, nav, learned)
            speed = pace * PLANNED_SPEED * session.link.clock.rate  # m per second of wall time
            settled = replans > 0 and spot != tuple(goal)
            path = plan(robot, pose[:2], spot, speed, around, session.check, settled, may_ask=True)
            if path is None:  # it stands (for good, as the others plan) until a way opens
                _drop_plan(robot)
                stuck_since = stuck_since or time.monotonic()
                if time.monotonic() - stuck_since > WAIT_LIMIT_S:
                    raise StepFailed(f"{robot.name}: no plan to its goal clear of the others")
                _hold(session, time.time() + PLAN_AGAIN_S)
                continue
            stuck_since, spot = None, tuple(path[-1][:2])
            try:
                _follow(session, path, limits, factor, nav)
                done = math.dist(spot, goal) < SETTLE_M or settles >= SETTLE_TRIES
                if done or _yet_to_pass(robot, spot):
                    return _moved(tuple(goal), spot)
                settles, spot = settles + 1, tuple(goal)  # its goal may be free by now: again
            except Reroute as exc:
                reroutes += 1
                if reroutes > MAX_REROUTES:
                    raise StepFailed(f"{robot.name}: no way through after {MAX_REROUTES} reroutes") from None
                around |= exc.around
                _back_off(session, exc.around, limits, factor, nav)
                here = session.pose()[:2]
                claim(robot, here, here, session.check)  # keep only where it stands: the others may go on
        raise StepFailed(f"{robot.name}: not there after {MAX_REPLANS} plans")
    finally:
        release(robot, session.link.poses.value)


def _back_off(session: Session, others: set[int], limits: motion.Limits, factor: float, nav: bool) -> None:
    """Give way to the robots of a deadlock: drive BACK_OFF_M straight away from them (or half or a quarter
    turn aside), where the map is free and the claim is granted, so the plan round them starts with room to
    pass; two robots stopped nose to nose are too close for any first stretch of a way round to be granted
    (the claims let nobody come nearer). Nowhere to go: it replans where it stands."""
    robot, redis = session.robot, coordination.connection()
    here = session.pose()[:2]
    held = [_capsule(pk, entry) for pk, entry in _hash(redis, "claims").items() if pk in others]
    for target in give_way(here, held, route.planner_for(robot)):
        if claim(robot, here, target, session.check) is not None:
            continue
        log.info("traffic: %s backs off to %s to give way to %s", robot.name, target, sorted(others))
        try:
            if nav:
                navigate(session, *target, travel_time(BACK_OFF_M * 2, math.pi, limits, factor))
            else:
                controller = motion.GoToGoal(target, limits, factor, CORNER_TOLERANCE)
                drive(session, controller, travel_time(BACK_OFF_M, math.pi, limits, factor), stall_s=STALL_S)
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
            here[0] + BACK_OFF_M * math.cos(heading + turn),
            here[1] + BACK_OFF_M * math.sin(heading + turn),
        )
        if planner is None or planner.free(*planner.to_cell(*target)):
            out.append(target)
    return out


def _measure_clock(session: Session) -> None:
    """Read odometry until the robot's clock rate is known (a link opened just now has not measured it), so
    its plan is timed at its real pace; a robot whose stamps say nothing is planned at rate 1."""
    deadline = time.monotonic() + 3 * motion.RATE_SPAN_S
    while not session.link.clock.measured and time.monotonic() < deadline:
        session.pose()
        session.check()


def _moved(goal, end) -> str:
    distance = math.dist(goal, end)
    if distance < 0.05:
        return ""
    return f" (its spot was taken: it stopped {distance:.1f} m {plain.compass(goal, end)} of it)"


def _follow(session: Session, path, limits, factor: float, nav: bool) -> None:
    """Drive the planned path stretch by stretch, each claimed first; the goal is the path's end (the goal
    asked for, or the free spot next to it when that was taken). The plan is never replanned on the way: the
    claims keep its order however late the robot runs (a replan would make a new order against robots already
    late on the old one).

    A robot never sets off on a stretch more than EARLY_S before its planned time: the plan is slower than the
    robot (PLANNED_SPEED), and one running ahead of it would meet robots planned to have left by then there. A
    nav stack drives at a pace of its own, which later plans are timed at (known_pace; until it is seen, the
    robot's speed limit: a stack slower than that is late, which the order allows for).
    A nav stack that gives up on a corner of the route (a goal its footprint cannot reach beside
    an obstacle) goes on to the next one; giving up on the goal itself ends the step."""
    robot, goal, planned = session.robot, path[-1][:2], path[0][2]
    legs = stretches(path)
    due = planned  # when the next stretch is planned to begin
    for i, (x, y, t, hold) in enumerate(legs):
        begins = due
        live.path(robot, [(round(p[0], 2), round(p[1], 2)) for p in legs[i:]], None)
        early = time.time() < due - EARLY_S
        if hold or early:  # a planned wait, or early: keep to the plan's times
            _hold(session, t if hold else due - EARLY_S)
        due = t
        if hold:
            continue
        pose = session.pose()
        wait_for(session, pose[:2], (x, y), (begins, t))
        last = i == len(legs) - 1
        target = tuple(goal) if last else (x, y)
        distance = math.dist(pose[:2], target)
        if nav:
            limit = travel_time(distance * 1.5, math.pi, limits, factor)
            sent = time.monotonic()
            try:
                navigate(session, *target, limit, stall_s=NAV_STALL_S)
            except Aborted:
                if last:
                    raise
                log.info(
                    "traffic: %s's nav stack gave up on a corner of its route, %s: on to the next",
                    robot.name,
                    target,
                )
                continue
            _note_pace(session, distance, time.monotonic() - sent)
        else:
            tolerance = motion.TOLERANCE if last else _tolerance(pose[:2], legs, i)
            controller = motion.GoToGoal(target, limits, factor, tolerance)
            drive(
                session,
                controller,
                travel_time(distance, math.pi, limits, factor),
                stall_s=STALL_S,
                goal=target,
            )


def _pace(limits: motion.Limits, factor: float, nav: bool, learned: float | None) -> float:
    """The pace a robot's plan is timed at (m per second of its clock): its speed limit at the factor asked
    for; a nav stack's pace as seen (learned), and until it is seen, the robot's speed limit. A plan faster
    than the robot only makes it late against its reservations, where the claims hold it; after its first
    stretch it replans at the pace seen (_follow). (A guess slower than the stack, 0.11 m/s for a TIAGo
    driving 0.5, made plans longer than the search's horizon, and robots early against all of them.)"""
    if not nav:
        return limits.linear * factor
    return learned or limits.linear


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
    return CORNER_TOLERANCE if turn > CORNER_TURN else WAYPOINT_TOLERANCE


def known_pace(robot_id: int) -> float | None:
    """The pace a robot's nav stack was seen to keep (m per second of the robot's clock), None if never seen."""
    raw = coordination.connection().hget(_key("pace"), str(robot_id))
    return float(raw) if raw else None


def _note_pace(session: Session, distance: float, elapsed: float) -> None:
    """Learn the nav stack's pace from a stretch it drove (turns and ramps included): later plans are timed
    by it. The stack chooses its own speed, which the portal can only observe."""
    if distance < PACE_MIN_M or elapsed <= 0:
        return
    seen = distance / elapsed / session.link.clock.rate
    known = known_pace(session.robot.pk)
    pace = seen if known is None else PACE_WEIGHT * seen + (1 - PACE_WEIGHT) * known
    coordination.connection().hset(_key("pace"), str(session.robot.pk), f"{pace:.4f}")


def _hold(session: Session, until: float) -> None:
    """A wait in the plan: stay until its time (another robot passes first), at most HOLD_S beyond now."""
    deadline = min(until, time.time() + HOLD_S)
    session.link.halt()
    while time.time() < deadline:
        session.check()
        session.pose()
