"""Traffic for the robots the portal moves: every motion reserved in space and time, claimed as it is driven.

The algorithms are plain (fleetcore.traffic), their numbers in one place (fleetcore.traffic_tuning); this
module plans and claims with them. Along its seams: the state every worker sees, in Redis (traffic_state: plans,
claims, waits, deadlocks, requests to make way), the database reads (traffic_fleet), the driving loop of a route
(execution.driving) and the make_way step (execution.make_way):

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
   asked to make way (ask_to_make_way: an instruction of the system's, with its cause, asked for through the
   signal execution.signals.make_way_asked, which the instruction layer answers); its make_way step moves it
   off the other's route (make_way.aside), waits for it to pass (make_way.until_passed) and comes back. A robot a
   stop holds or someone leases is never asked (access.holds): it stands for good, the other goes round it,
   or stands and plans again, and fails saying who is in the way.

Robots with their own navigation stack take the same route as goals, one stretch at a time, each claimed
first: their goals never conflict with the reservations (execution.steps.navigate).
"""

from __future__ import annotations

import asyncio
import functools
import itertools
import logging
import math
import time

import live
from execution import blocking, coordination, route, signals
from execution import traffic_fleet as fleet
from execution import traffic_state as state
from execution.steps import Session, StepFailed, at_rest
from fleetcore import traffic as plain
from fleetcore import traffic_tuning as tune
from robots.models import Robot

log = logging.getLogger(__name__)


class Reroute(Exception):
    """Replan from here, around these robots (ids), which stand in the way; gave_way: to break a deadlock."""

    def __init__(self, around: set[int], gave_way: bool = False) -> None:
        super().__init__(around)
        self.around, self.gave_way = around, gave_way


def obstacles(redis, robot_id: int, now: float, around: set[int] = frozenset()):
    """What a newcomer must keep clear of: the paths others reserved and the stretches they hold now (in the
    table); where those robots will stand once arrived, and the robots standing (exact discs, from when).
    Robots in `around` count as standing where they hold room now, for good (a reroute goes round them)."""
    table, still = plain.ReservationTable(), []
    plans, claims = state.read(redis, "plans"), state.read(redis, "claims")
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
        held = plain.entry_capsule(pk, entry)
        if pk in around or pk not in plans:  # not planned yet: where it stands, for good, as far as we know
            still.append((held, -math.inf))
        else:
            table.reserve(
                str(pk),
                plain.swept_cells(held.a, held.b, held.r + tune.SPACING_M),
                now - 1.0,
                now + tune.HOLD_S,
            )
    still.extend(_standing(redis, {robot_id, *claims, *plans}))
    return table, still


async def plan(
    robot: Robot,
    start,
    goal,
    speed: float,
    around: set[int] = frozenset(),
    progress=None,
    settled: bool = False,
    may_ask: bool = False,
    first: bool = False,
) -> list[tuple]:
    """Plan and reserve the robot's timed path [(x, y, t), ...] from start to goal (wall-clock t), in its
    turn (planning_turn): each plan sees the ones reserved before it. Claims are never held up by a plan.
    settled: the goal is the spot an earlier plan of this trip chose; it moves only if a robot would touch it.
    may_ask: robots parked in the way, idle, may be asked to make way (the plan then passes where they stand
    once they have moved; ask_to_make_way sends them the instruction after the turn).
    first: planned before every robot waiting for its turn (a robot making way: the others wait for it); the
    others, the longest trip first (its expected time: the straight line at `speed`)."""
    asked = time.monotonic()
    progress = _now_and_then(progress)
    longest = tune.FIRST_IN_TURN_S if first else math.dist(start[:2], goal[:2]) / max(speed, 1e-3)
    async with state.planning_turn(robot, progress, longest):
        began = time.monotonic()
        path = await blocking.call(_plan, robot, start, goal, speed, around, progress, settled, may_ask)
    done = time.monotonic()
    if may_ask:
        await blocking.call(ask_to_make_way, robot)
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
        if time.monotonic() - last >= tune.PROGRESS_EVERY_S:
            last = time.monotonic()
            progress()

    return call


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
    radius = fleet.reach(robot)
    now = time.time()
    path, heeds = None, 0.0  # heeds: how far ahead the plan heeded the others' reservations
    if planner is not None:
        redis = coordination.connection()
        table, still = obstacles(redis, robot.pk, now, around)  # a snapshot: no lock
        # plan wider than claims need: a robot off its line still gets them
        grow = tune.CLAIM_MARGIN + tune.PLAN_MARGIN
        exact, still = still, [(_grown(c, grow), since) for c, since in still]
        goal = free_goal(robot, goal, radius, exact if settled else still, planner, start)
        still = _stoppable(goal, radius, still, exact)
        if not planner.free(*planner.to_cell(*goal)):  # the search takes the goal's point to be free ground
            log.info(
                "traffic: %s's goal %s is off the free ground: it drives the map route", robot.name, goal
            )
            path = _timed([tuple(start), *route.route(robot, tuple(start), tuple(goal))], speed, now)
            state.reserve(redis, robot, path, radius, now, 0.0)
            return path
        path, heeds = _search(robot, passable, start, goal, speed, now, table, still, progress)
        through = _detour(path, start, goal, planner) if may_ask else None
        idle = _idle_in_the_way(redis, robot, through, exact) if through else {}
        if idle:  # the same search with them gone from where they stand after MAKE_WAY_HOLD_S
            for pk, disc in idle.items():
                cells = plain.footprint_cells(disc.a, disc.r)
                table.reserve(str(pk), cells, now - 1.0, now + tune.MAKE_WAY_HOLD_S)
            rest = [(c, since) for c, since in still if int(c.label) not in idle]
            passing, passing_heeds = _search(robot, passable, start, goal, speed, now, table, rest, progress)
            asked = {pk: disc for pk, disc in idle.items() if passing and plain.passes(passing, disc, radius)}
            if asked:  # (a plan that went round them all the same asks nobody)
                path, heeds = passing, passing_heeds
                state.request_way(redis, robot, radius, asked, through)
    if planner is None:  # no map: the straight line, timed, which the claims keep apart
        path, heeds = _timed([tuple(start), tuple(goal)], speed, now), 0.0
    if path is None:
        log.info("traffic: %s has no conflict-free plan to %s; it stands and plans again", robot.name, goal)
        return None
    # one transaction, its own entries
    state.reserve(coordination.connection(), robot, path, radius, now, heeds)
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
        (_grown(near, tune.CLAIM_MARGIN) if plain.segment_distance(goal, goal, grown.a, grown.b) < grown.r + radius
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
        return narrow(cell) and any(math.dist(point, end) < tune.END_M for end in ends)

    return passing, passable


def _search(robot: Robot, passable, start, goal, speed: float, now: float, table, still, progress):
    """The first plan of searches() that finds one on these cells (passable), and how far ahead it heeded the
    others' reservations (all the way); (None, 0.0) when none finds one."""
    radius = fleet.reach(robot)
    for pace in searches(speed):
        search = plain.SpaceTimeSearch(
            passable, radius, pace, plain.pad(now), horizon_s=tune.HORIZON_S, spacing=tune.SPACING_M
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
    if path is not None and _length(path) <= tune.DETOUR_FACTOR * math.dist(start, goal) + tune.DETOUR_M:
        return None
    through = planner.plan(tuple(start), tuple(goal))
    if not through or (
        path is not None and _length(path) <= tune.DETOUR_FACTOR * _length(through) + tune.DETOUR_M
    ):
        return None
    return [tuple(start), *through]


def _idle_in_the_way(redis, robot: Robot, through, exact) -> dict[int, plain.Capsule]:
    """The robots standing on the map route (within reach of it) that are idle, not asked already, not
    refused lately and not made way for this robot lately: {id: where they stand}. Robots under traffic,
    busy ones (about to set off: plans go round them, but they are not asked) and others' goals are not
    idle."""
    under = _not_to_ask(redis, robot)
    return {
        int(disc.label): disc
        for disc, since in exact
        if since == -math.inf
        and int(disc.label) not in under
        and plain.passes(through, disc, fleet.reach(robot))
    }


def _not_to_ask(redis, robot: Robot) -> set[int]:
    """The robots this one may not ask to make way: under traffic, busy, kept still (by a person's stop or
    hold), asked already, or that made way for it lately."""
    asked = {
        pk for pk, e in state.read(redis, "makeway").items() if not e.get("done") or e["for"] == robot.pk
    }
    return (
        set(state.read(redis, "plans"))
        | set(state.read(redis, "claims"))
        | asked
        | fleet.busy_ids()
        | fleet.kept_still()
    )


def ask_to_make_way(robot: Robot) -> None:
    """Ask each robot this one asked to make way (traffic_state.request_way) for a make_way instruction of the
    system's (no user; its cause names the instruction this robot runs and its person), through the signal
    make_way_asked: the instruction layer, above traffic, submits it, and the robot's hold, lease, schedule and
    state are checked as for any automatic instruction (execution.dispatch). A refusal is kept in the table
    (that robot is not asked again by anyone for MAKE_WAY_TTL_S) and said."""
    redis = coordination.connection()
    asked = {
        pk: e for pk, e in state.read(redis, "makeway").items() if e.get("for") == robot.pk and not e["sent"]
    }
    if not asked:
        return
    cause = f"make way for {robot.name}{fleet.running(robot)}"
    names = dict(Robot.objects.filter(pk__in=list(asked)).values_list("pk", "name"))
    for pk, entry in asked.items():
        # before its step may read it
        state.write(redis, "makeway", pk, {**entry, "sent": True, "refused": ""})
        answers = signals.make_way_asked.send(sender=Robot, robot=robot, asked=names[pk], cause=cause)
        for _, refused in answers:
            if refused is not None:
                state.write(redis, "makeway", pk, {**entry, "sent": True, "refused": refused})
                log.info("traffic: %s cannot make way for %s: %s", names[pk], robot.name, refused)


def searches(speed: float) -> list[float]:
    """The paces of the searches tried in turn until one finds a plan: the robot's; a fast robot's again at
    SLOW_PLAN_MPS (its moves are fewer ticks of search, and it finds plans a fast one does not). Each heeds
    the reservations all the way to the goal: a plan blind to them beyond a window (replanned before the
    window ran out, against robots late on their plans) or as a last resort let the order go round."""
    return [speed, tune.SLOW_PLAN_MPS] if speed > tune.SLOW_PLAN_MPS * 1.2 else [speed]


def free_goal(robot: Robot, goal, radius: float, still, planner, start) -> tuple[float, float]:
    """The goal, or the nearest free spot to it when a robot stands too close (one that stopped a little
    short of its own spot, say): where this robot can stop clear of everyone."""
    discs = [capsule for capsule, _ in still]  # all of a stretch a robot holds, not only where it began
    if plain.clear_of(tuple(goal), radius, discs, 0.05) is None:
        return tuple(goal)
    is_free = lambda x, y: planner.free(*planner.to_cell(x, y))  # noqa: E731
    spot = plain.free_spot(
        tuple(goal), radius, discs, is_free, prefer=tuple(start), margin=tune.CLAIM_MARGIN + 0.01
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


def claim(robot: Robot, start, end, progress=None, everyone=None, planned=None, why=None) -> int | None:
    """Claim the stretch from start to end for the robot (replacing its previous claim); the id of a robot in
    the way (holding room there, or standing there, or planned there before this one: first_to_pass), or None
    when the claim is the robot's.

    everyone: the robots standing (standing()), when the caller has them (a waiting robot reads them less
    often than it tries). planned: (t0, t1), the stretch's times in the robot's plan: the claim keeps the
    plans' order (a robot planned there first and not yet past goes first), and the robot's progress (t0) is
    written with it for the others to do the same. why: a list, given the reason a claim was refused ("room":
    the robot in the way holds or stands in the room; "order": it is planned there first)."""
    radius, redis = fleet.reach(robot), coordination.connection()
    if everyone is None:
        everyone = _standing(redis, {robot.pk})  # the slow part (database), before the transaction
    return state.try_claim(redis, robot, start, end, radius, everyone, planned, why, progress)


def _standing(redis, exclude: set[int]) -> list[tuple[plain.Capsule, float]]:
    """The robots not under traffic (traffic_fleet.standing), where they stand or parked."""
    return fleet.standing(state.read(redis, "parked"), exclude)


def yet_to_pass(robot: Robot, spot) -> bool:
    """Whether another robot under way has yet to pass near where this one stands (by its plan, from where
    its claim begins): then this one does not plan again from there (the order would have that one first
    where it must pass this one), it stays where it is, and that one goes round it as round any robot
    parked (run br: a robot planning again for its goal, taken before, waited by the order for a Husky
    that waited for its room)."""
    redis = coordination.connection()
    claims, radius = state.read(redis, "claims"), fleet.reach(robot)
    for pk, entry in state.read(redis, "timed").items():
        if pk == robot.pk or pk not in claims:
            continue
        progress = claims[pk].get("t", entry["path"][0][2])
        near = radius + entry["r"] + tune.ORDER_ZONE + tune.CLAIM_MARGIN
        rest = [tuple(claims[pk]["a"]), *(tuple(p[:2]) for p in entry["path"] if p[2] >= progress)]
        if any(plain.segment_distance(spot, spot, p, q) < near for p, q in itertools.pairwise(rest)):
            return True
    return False


async def wait_for(session: Session, start, end, planned=None, ahead=(), gone_round=frozenset()) -> None:
    """Claim the stretch, waiting while another robot is in the way (or is planned there first: claim());
    raise Reroute to break a deadlock or to go around a robot that is not under way; StepFailed after
    WAIT_LIMIT_S. planned: the stretch's (t0, t1) in the robot's plan; ahead: the rest of the plan's points.

    A parked, idle robot this trip already went round (gone_round) and still stands in the way is asked to
    make way, once, along `ahead`: a plan round it that the claims refuse again would be made the same
    (robots parked shoulder to shoulder, 0.6 m apart: "goes round robot3" four times, then "no way through").

    A waiting robot holds only the room it stands in (others may pass behind it) and tries every WAIT_POLL_S;
    every NOTE_WAIT_S it reads the robots standing afresh, notes whom it waits for, keeps its claim alive and
    looks for a cycle of waits."""
    robot, redis = session.robot, coordination.connection()
    started = same_since = noted = told = time.monotonic()
    last, name, everyone, why, asked = None, "", None, [], False
    while (
        blocker := await blocking.call(claim, robot, start, end, session.check, everyone, planned, why)
    ) is not None:
        now = time.monotonic()
        if blocker != last:
            if last is None:  # it waits where it comes to rest: it holds that room, not the stretch behind
                here = (await at_rest(session))[:2]
                await blocking.call(claim, robot, here, here, session.check, everyone, planned)
            same_since, last = now, blocker
            name = await blocking.call(fleet.name_of, blocker)
            log.debug("traffic: %s waits for %s to go from %s to %s", robot.name, name, start, end)
            await blocking.call(live.path, robot, None, name)
            noted = -math.inf
        if now - noted >= tune.NOTE_WAIT_S:
            noted = now
            everyone = await blocking.call(_note_wait, redis, robot, blocker, why[-1], (start, end))
            parked = now - same_since > tune.REROUTE_AFTER_S and await blocking.call(
                _parked, redis, blocker, now - same_since
            )
            if parked:
                if (
                    not asked
                    and blocker in gone_round
                    and blocker not in await blocking.call(_not_to_ask, redis, robot)
                ):
                    await blocking.call(_ask_way, redis, robot, blocker, [start, *ahead])
                    asked, same_since = True, now
                    continue
                log.info("traffic: %s goes round %s, which stands in its way", robot.name, name)
                raise Reroute({blocker})
        if now - told >= tune.TELL_WAIT_S:
            told = now
            doing = await blocking.call(_doing, redis, blocker)
            log.info("traffic: %s has waited %.0f s for %s (%s)", robot.name, now - started, name, doing)
        if now - started > tune.WAIT_LIMIT_S:
            raise StepFailed(f"{robot.name}: waited {tune.WAIT_LIMIT_S:.0f} s for {name} to make way")
        session.check()
        await asyncio.sleep(tune.WAIT_POLL_S)
        await (
            session.pose()
        )  # a robot waiting still reads where it is (and odometry that stops fails the step)
    if last is not None:
        await blocking.call(live.path, robot, None, None)


def _note_wait(redis, robot: Robot, blocker: int, why: str, stretch) -> list:
    """Note whom the robot waits for (and why), keep its claim alive, look for a cycle of waits (Reroute when
    this robot is the one to give way); the robots standing, read afresh."""
    everyone = _standing(redis, {robot.pk})
    wanted = [[round(v, 2) for v in point[:2]] for point in stretch]
    entry = {"for": blocker, "why": why, "to": wanted, "expires": time.time() + 2.0}
    state.write(redis, "waits", robot.pk, entry)
    state.renew(redis, robot.pk)
    _check_deadlock(redis, robot.pk)
    return everyone


def _ask_way(redis, robot: Robot, blocker: int, route_points) -> None:
    """Ask a parked robot in the way to make way along the route (it waits on: _parked() is False while the
    request stands)."""
    state.request_way(redis, robot, fleet.reach(robot), {blocker: None}, route_points)
    ask_to_make_way(robot)


def _doing(redis, robot_id: int) -> str:
    """What a robot in the way is doing, as the traffic tables say (for the log of a long wait)."""
    waits = state.read(redis, "waits")
    if robot_id in waits:
        return f"it waits for #{waits[robot_id].get('for')}"
    if robot_id in state.read(redis, "claims"):
        return "it holds room under way"
    return "it stands, not under traffic"


def _parked(redis, blocker: int, waited: float) -> bool:
    """Whether a robot in the way is parked (go round it), not one under way or about to be (wait for it)."""
    if blocker in state.read(redis, "claims"):
        return False
    request = state.read(redis, "makeway").get(blocker)
    if request is not None and request.get("sent") and not request.get("refused") and not request.get("done"):
        return False  # it was asked to make way (for this robot or another): it will
    return not fleet.is_busy(blocker) or waited > tune.BUSY_WAIT_S


def _check_deadlock(redis, robot_id: int) -> None:
    """If this robot is in a cycle of waits and is the one to give way (traffic_state.break_deadlock: the one
    that gave way least often, then the highest id), it does: Reroute round the others of the cycle."""
    broken = state.break_deadlock(redis, robot_id)
    if broken is None:
        return
    cycle, held, why = broken
    log.info(
        "traffic: deadlock among robots %s broken by %s (room held: %s; waits: %s)",
        cycle,
        robot_id,
        held,
        why,
    )
    raise Reroute({int(pk) for pk in cycle} - {robot_id}, gave_way=True)
