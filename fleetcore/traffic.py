"""Traffic for a fleet on one map (plain code, no Django): free goal spots, space-time A* (cooperative A*,
prioritized planning) against the reservation table (`fleetcore/reservations.py`), the plans' order kept at run
time, and wait-for cycles.

Why prioritized planning on a reservation table (Silver 2005, "Cooperative Pathfinding"; Open-RMF's traffic
schedule is the same idea) rather than conflict-based search: robots get instructions one at a time, each
instruction's robots are planned when it is dispatched, and robots already under way must not be replanned by a
newcomer. Prioritized planning fits that arrival order (first come, first reserved), costs one search per robot,
and a robot that cannot find a conflict-free plan waits or detours. Its known gap, a deadlock when robots wait on
each other at run time, is closed by the wait-for cycle check (`wait_cycle`) and a reroute.

Cells, footprints and time are the reservation table's (`fleetcore/reservations.py`); execution/ still names its
footprint_cells, swept_cells and leg_slots through this module, which imports them for that.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

from fleetcore import traffic_tuning as tune
from fleetcore.reservations import (
    FOREVER,
    TRAFFIC_CELL,
    Cell,
    Point,
    ReservationTable,
    Spans,
    cell_of,
    center_of,
    disc_offsets,
    footprint_cells,  # noqa: F401
    leg_slots,  # noqa: F401
    swept_cells,  # noqa: F401
)

SPOT_MARGIN = 0.3  # m kept between two robots' discs at their goals (more than execution.traffic plans with)
SPOT_STEP = 0.1  # m between the rings searched for a free spot
SPOT_SEARCH_M = 4.0  # m: how far from the place a free spot is looked for
COMPASS = ("east", "north-east", "north", "north-west", "west", "south-west", "south", "south-east")


@dataclass(frozen=True)
class Disc:
    """Something round that takes room: a parked robot, another robot's goal. label names it for a person."""

    x: float
    y: float
    r: float
    label: str = ""

    def distance(self, point: Point) -> float:
        """From a point to the disc's centre."""
        return math.dist(point, (self.x, self.y))


def clear_of(point: Point, radius: float, discs: Iterable[Disc | Capsule], margin: float = SPOT_MARGIN):
    """The first disc (or capsule: a robot holding a stretch of its way takes all of it) a robot of this radius
    at point would touch (within margin); None when clear."""
    for disc in discs:
        if disc.distance(point) < radius + disc.r + margin:
            return disc
    return None


def free_spot(
    target: Point,
    radius: float,
    taken: Sequence[Disc | Capsule],
    is_free: Callable[[float, float], bool],
    prefer: Point | None = None,
    step: float = SPOT_STEP,
    search_m: float = SPOT_SEARCH_M,
    margin: float = SPOT_MARGIN,
) -> Point | None:
    """The spot nearest to target where a robot of this radius stands on free ground, clear of every taken disc.

    Rings of growing radius are searched; on the first ring with free spots the one nearest to `prefer` (the
    robot's position) wins, so the robot stops on its own side and does not drive round the place. None when
    nothing within search_m is free.
    """
    for ring in range(round(search_m / step) + 1):
        r = ring * step
        count = 1 if ring == 0 else max(8, math.ceil(2 * math.pi * r / step))
        spots = [
            (round(target[0] + r * math.cos(a), 3), round(target[1] + r * math.sin(a), 3))
            for a in _angles(count)
        ]
        fits = [p for p in spots if is_free(*p) and clear_of(p, radius, taken, margin) is None]
        if fits:
            return min(fits, key=lambda p: math.dist(p, prefer)) if prefer else fits[0]
    return None


def _angles(count: int) -> list[float]:
    return [2 * math.pi * i / count for i in range(count)]


def compass(origin: Point, point: Point) -> str:
    """The direction from origin to point in words ("east", "north-west")."""
    angle = math.atan2(point[1] - origin[1], point[0] - origin[0])
    return COMPASS[round(angle / (math.pi / 4)) % 8]


def segment_distance(p: Point, q: Point, a: Point, b: Point) -> float:
    """The least distance between segments pq and ab (points are segments of length zero)."""
    if _cross(p, q, a, b):
        return 0.0
    return min(
        _point_segment(p, a, b), _point_segment(q, a, b), _point_segment(a, p, q), _point_segment(b, p, q)
    )


def nearest_on(p: Point, a: Point, b: Point) -> Point:
    """The point of the segment a-b nearest to p."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    if length2 == 0.0:
        return a
    f = max(0.0, min(1.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2))
    return (a[0] + f * dx, a[1] + f * dy)


def _point_segment(p: Point, a: Point, b: Point) -> float:
    return math.dist(p, nearest_on(p, a, b))


def _cross(p: Point, q: Point, a: Point, b: Point) -> bool:
    def side(o, u, v):
        return (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0])

    d1, d2, d3, d4 = side(a, b, p), side(a, b, q), side(p, q, a), side(p, q, b)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


@dataclass(frozen=True)
class Capsule:
    """The room a robot takes for a stretch of its route: every point within r of the segment a-b (a disc
    when a == b: a robot standing). label names the robot."""

    a: Point
    b: Point
    r: float
    label: str = ""

    def distance(self, point: Point) -> float:
        """From a point to the capsule's segment."""
        return _distance(point, self)


def _distance(p: Point, capsule: Capsule) -> float:
    """From a point to a capsule's segment (to its centre when it is a disc: most are robots standing)."""
    if capsule.a == capsule.b:
        return math.dist(p, capsule.a)
    return segment_distance(p, p, capsule.a, capsule.b)


def approaches(
    p0: Point, p1: Point, radius: float, other: Capsule, margin: float = 0.0, slack: float = 1e-6
) -> bool:
    """Whether a robot of this radius moving from p0 to p1 comes nearer to `other` than their radii (plus
    margin) allow, and nearer than it already is (by more than slack). A robot already close may still move
    away or sideways."""
    near = segment_distance(p0, p1, other.a, other.b)
    return near < radius + other.r + margin and near < segment_distance(p0, p0, other.a, other.b) - slack


def first_in_the_way(
    p0: Point, p1: Point, radius: float, others, margin: float = 0.0, slack: float = 1e-6
) -> Capsule | None:
    """The first capsule a move from p0 to p1 would come too near (approaches); None when the way is clear."""
    for other in others:
        if approaches(p0, p1, radius, other, margin, slack):
            return other
    return None


class Clearance:
    """How far a robot of some radius keeps from the robots standing (exact discs, each from its time on).

    A move may not end nearer to a standing robot than their radii allow unless it ends no nearer than it
    starts: a robot that starts too close (robots parked side by side) may still move away."""

    def __init__(self, standing: Sequence[tuple[Capsule, float]], radius: float, pad, exact=None) -> None:
        self.standing, self.radius, self.pad = list(standing), radius, pad
        self.exact: dict[Cell, Point] = dict(exact or {})  # cells measured at a point, not their centre
        self._gaps: dict[Cell, list[tuple[float, float]]] = {}

    def gaps(self, c: Cell) -> list[tuple[float, float]]:
        """(since, gap) for each standing robot near the cell's centre: gap < 0 means too close."""
        if c not in self._gaps:
            p = self.exact.get(c) or center_of(c)
            self._gaps[c] = [
                (since, gap)
                for disc, since in self.standing
                if (gap := _distance(p, disc) - disc.r - self.radius) < TRAFFIC_CELL * 2
            ]
        return self._gaps[c]

    def gap(self, c: Cell, t: float) -> float:
        """The least gap at the cell to the robots standing by time t (a wide gap when none is near)."""
        near = self.gaps(c)
        if not near:  # most cells: nobody stands near
            return TRAFFIC_CELL * 2
        return min((gap for since, gap in near if since <= t + self.pad(t)), default=TRAFFIC_CELL * 2)

    def may_move(self, c: Cell, n: Cell, t: float, loose: bool = False) -> bool:
        """Whether a move from c to n keeps clear, or at least gets no nearer; loose (still within where the
        robot stood): half a cell nearer is let pass, as cell centres misplace the robot's real start."""
        end = self.gap(n, t)
        return end >= 0 or end >= self.gap(c, t) - (TRAFFIC_CELL / 2 if loose else 1e-9)

    def stays(self, c: Cell, t: float) -> bool:
        """Whether the robot may stay at the cell from t on: no robot will come to stand too close later."""
        return all(gap >= 0 for since, gap in self.gaps(c) if since > t)

    def leg_clear(self, a, b) -> bool:
        """Whether the straight timed leg a -> b keeps clear of the robots standing by its end."""
        t = b[2]
        active = [disc for disc, since in self.standing if since <= t + self.pad(t)]
        return first_in_the_way(a[:2], b[:2], self.radius, active) is None


SHORTCUT_REACH = 40  # points ahead a straight leg may join (string pulling costs grow with the square)
MOVES = [(dc, dr, math.hypot(dc, dr)) for dc in (-1, 0, 1) for dr in (-1, 0, 1) if dc or dr]
DETOUR = (1.5, 10)  # the longest detour searched: this many times the shortest way, plus this many cells


@dataclass
class SpaceTimeSearch:
    """Space-time A* on the traffic grid for one robot, against a reservation table (cooperative A*).

    passable(cell): the robot may stand there (the map, inflated by its size). speed: m/s it is planned at.
    pad(t): seconds added on both sides of each reserved interval (timing uncertainty grows with time).
    The search runs on safe intervals (SIPP: Phillips and Likhachev 2011, "Safe Interval Path Planning for
    Dynamic Environments"): a state is a cell and one of its free spells (the time between two reservations
    of the footprint there), reached as early as it can be; a move goes to a neighbour (a tick, one cell's
    travel), after waiting where it stands as long as it takes, once for each free spell of the neighbour that
    the wait can reach. A wait of any length is one state: searches that stepped through time spent their
    60,000 states waiting where a crowd passes, and the robot then drove a plan blind to the reservations
    (8 such plans in a 32-robot run, each in a deadlock after). The heuristic is the exact distance on
    the static grid (one Dijkstra from the goal), so the search only explores detours and waits that the
    reservations force. Reservations are heeded all the way to the goal (a windowed search, Silver 2005,
    left plans blind to the others beyond 30 s, replanned against robots late on theirs: the order kept at
    run time went round). spacing: metres added to the radius against the reservations only (not against
    the robots standing), so plans keep more room between robots than the claims ask.
    """

    passable: Callable[[Cell], bool]
    radius: float
    speed: float
    pad: Callable[[float], float] = lambda t: 0.5
    max_expansions: int = 60_000
    horizon_s: float = 240.0
    spacing: float = 0.0  # m added to the radius against the reservations (not against robots standing)
    expanded: int = field(default=0, init=False)  # states the last plan() expanded

    def plan(
        self,
        start: Point,
        goal: Point,
        t0: float,
        table: ReservationTable,
        robot: str = "",
        standing: Sequence[tuple[Capsule, float]] = (),
        progress: Callable[[], None] | None = None,
    ) -> list[tuple[float, float, float]] | None:
        """A timed path [(x, y, t), ...] from start to goal avoiding the table's reservations at their times
        and the robots standing, exactly, as discs (each from its time
        `since` on: a robot parked now has -inf, another's goal the time it arrives there), ending where the
        robot may stay; consecutive equal points are waits. The cells the robot stands on at the start are
        its own until it moves. progress() is called every few hundred steps of work (keep a lock alive,
        honour a stop). None: no plan."""
        self._progress = progress or (lambda: None)
        s, g = cell_of(start), cell_of(goal)
        distance = self._distances(g, s)
        if s not in distance:
            return None
        tick = TRAFFIC_CELL / self.speed
        offsets = disc_offsets(self.radius + self.spacing)
        near = Clearance(standing, self.radius, self.pad, {s: start, g: goal})
        self._near = near
        busy = table.intervals(robot)
        mine = {(s[0] + dc, s[1] + dr) for dc, dr in offsets}
        feet: dict[tuple[Cell, bool], Spans] = {}

        def held(c: Cell, own: bool = False) -> Spans:
            """When others hold some of its footprint at c, widened by the pad, cached; own: less the room it
            stood on at the start (its own until it has left it)."""
            if (c, own) not in feet:
                foot = [(c[0] + dc, c[1] + dr) for dc, dr in offsets]
                spans = busy.union(x for x in foot if not (own and x in mine))
                feet[c, own] = Spans((a - self.pad(a), b + self.pad(b)) for a, b in spans.pairs())
            return feet[c, own]

        squeezed = near.gap(s, t0) < 0  # it starts nearer to a robot standing than it should come
        if not self._passes_those_standing(s, g, distance, near, t0):
            return None
        first = held(s, True).gap_at(t0)
        if first is None:
            return None
        counter = itertools.count()
        start_state = (s, first)
        # Of states as good as each other, the one queued first is expanded first.
        openq = [(distance[s] * tick, next(counter), start_state, t0)]
        parent: dict = {start_state: None}
        times = {start_state: t0}
        for expansions in range(self.max_expansions):
            if not openq:
                break
            if expansions % 500 == 499:
                self._progress()
            _, _, state, t = heapq.heappop(openq)
            if t > times[state]:
                continue  # reached earlier since it was queued
            (c, gap), own = state, state[0] in mine
            self.expanded = expansions + 1
            if c == g and not held(c).overlaps(t, FOREVER) and near.stays(c, t):
                return self._timed(state, parent, times, start, goal, table, robot)
            until = held(c, own).gap_end(gap)  # it may wait here until then, and must have left by then
            for dc, dr, d in MOVES:
                n = (c[0] + dc, c[1] + dr)
                if n not in distance:
                    continue
                dt, entering, there = d * tick, held(n, own), held(n, n in mine)
                leave = t
                while True:  # each gap at n it can get to by waiting here for it: a state of its own
                    leave = there.free_from(entering.free_from(leave, dt), dt)
                    if entering.overlaps(leave, leave + dt):
                        continue  # the two views of n differ (leaving its own start): look again
                    t1 = leave + dt
                    if t1 > until or t1 - t0 > self.horizon_s:
                        break
                    arrival = there.gap_at(t1)
                    if arrival is None or not near.may_move(c, n, t1, loose=squeezed and own):
                        break
                    nxt = (n, arrival)
                    if t1 < times.get(nxt, FOREVER):
                        parent[nxt], times[nxt] = (state, leave), t1
                        heapq.heappush(openq, (t1 - t0 + distance[n] * tick, next(counter), nxt, t1))
                    leave = there.gap_end(arrival)  # the next gap begins after the next interval
                    if leave == FOREVER:
                        break
                    leave = there.ends[arrival]
        return None

    def _distances(self, goal: Cell, start: Cell) -> dict[Cell, float]:
        """Cells from which the goal is reachable on the static grid, with their distance to it (in cells).
        The goal's and the start's cells count as free: the caller knows that those points are (a cell's
        centre may be too near a wall while the point in it is not). Cells farther from the goal than the start
        is, by more than DETOUR (times, plus cells), are left out: the search makes no such detours."""
        dist = {goal: 0.0}
        heap = [(0.0, goal)]
        limit = math.inf
        ground: dict[Cell, bool] = {start: True}  # passable(), asked once per cell (up to 8 asked it again)
        for pops in itertools.count():
            if not heap:
                break
            if pops % 5000 == 4999:
                self._progress()
            d, c = heapq.heappop(heap)
            if d > limit:
                return {cell: known for cell, known in dist.items() if known <= limit}
            if d > dist.get(c, math.inf):
                continue
            if c == start:
                limit = d * DETOUR[0] + DETOUR[1]
            for dc, dr, step in MOVES:
                n = (c[0] + dc, c[1] + dr)
                nd = d + step
                if nd >= dist.get(n, math.inf):
                    continue
                free = ground.get(n)
                if free is None:
                    free = ground[n] = self.passable(n)
                if free:
                    dist[n] = nd
                    heapq.heappush(heap, (nd, n))
        return dist

    def _passes_those_standing(self, s: Cell, g: Cell, distance, near: Clearance, t0: float) -> bool:
        """Whether the goal can be reached past the robots standing at t0 at all, reservations aside (greedy
        best-first, a move as loose as the search ever allows). Robots standing never leave, and the others
        only add to what is in the way: where this fails, the search would fail too, after spending all its
        expansions on waits (two seconds, in the turn the whole fleet waits for). It did not fire in the
        32-robot runs an to at, whose failed searches all had a way past those standing."""
        seen, todo = {s}, [(distance[s], s)]
        while todo:
            _, c = heapq.heappop(todo)
            if c == g:
                return True
            for dc, dr, _ in MOVES:
                n = (c[0] + dc, c[1] + dr)
                if n in distance and n not in seen and near.may_move(c, n, t0, loose=True):
                    seen.add(n)
                    heapq.heappush(todo, (distance[n], n))
        return False

    def _timed(self, state, parent, times, start: Point, goal: Point, table, robot):
        """The timed points of the found path, from the real start to the real goal: a wait where the robot
        leaves a cell later than it got there."""
        s, g = cell_of(start), cell_of(goal)

        def point(c: Cell) -> Point:
            return start if c == s else goal if c == g else center_of(c)

        points = []
        while state is not None:
            points.append((*point(state[0]), times[state]))
            if parent[state] is not None:
                before, leave = parent[state]
                if leave > times[before]:
                    points.append((*point(before[0]), leave))
                state = before
            else:
                state = None
        points.reverse()
        points[-1] = (goal[0], goal[1], points[-1][2])
        return self._shortcut(simplify(points), table, robot)

    def _shortcut(self, points, table: ReservationTable, robot: str):
        """Straighten the grid's staircase: join two points by a straight leg when no wait lies between and
        the leg is on free ground and free of reservations over the time between them (string pulling)."""
        out, i = [points[0]], 0
        while i < len(points) - 1:
            j = i + 1
            for k in range(min(len(points) - 1, i + SHORTCUT_REACH), i + 1, -1):
                self._progress()
                if self._straight_ok(points[i : k + 1], table, robot):
                    j = k
                    break
            out.append(points[j])
            i = j
        return out

    def _straight_ok(self, run, table: ReservationTable, robot: str) -> bool:
        (x0, y0, _), (x1, y1, _) = run[0], run[-1]
        if any(a[:2] == b[:2] for a, b in itertools.pairwise(run)):
            return False  # a wait lies between: keep it
        n = max(1, math.ceil(math.dist((x0, y0), (x1, y1)) / (TRAFFIC_CELL / 2)))
        if not all(
            self.passable(cell_of((x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n))) for i in range(n + 1)
        ):
            return False
        if not self._near.leg_clear(run[0], run[-1]):
            return False
        return table.leg_free(run[0], run[-1], self.radius + self.spacing, self.pad, robot)


def simplify(points: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
    """Drop the middle points of straight runs (same direction, no wait), keeping every turn and wait."""
    if len(points) < 3:
        return points
    out = [points[0]]
    for prev, cur, nxt in zip(points, points[1:], points[2:], strict=False):
        d1 = (round(cur[0] - prev[0], 6), round(cur[1] - prev[1], 6))
        d2 = (round(nxt[0] - cur[0], 6), round(nxt[1] - cur[1], 6))
        if d1 != d2 or d1 == (0.0, 0.0):
            out.append(cur)
    out.append(points[-1])
    return out


PRECEDENCE_STEP = 0.1  # m between the points of another's plan compared with a stretch (first_to_pass)


@dataclass(frozen=True)
class Planned:
    """Another robot's plan as its stretches are checked against it: its timed path [(x, y, t), ...], its
    radius, its progress (the planned time of the stretch it holds now: what lies before is behind it), and
    the time up to which its plan heeded the others' reservations (beyond, its order means nothing)."""

    label: str
    path: Sequence[tuple[float, float, float]]
    r: float
    progress: float
    until: float = math.inf


def first_to_pass(
    a: Point,
    b: Point,
    ta: float,
    tb: float,
    radius: float,
    others: Iterable[Planned],
    zone: float = 0.0,
):
    """The first of the others whose plan has it near the stretch a -> b (planned from ta to tb) earlier than
    this robot's plan has it there, and which has not got past there yet: this robot lets it pass first;
    None when it goes first everywhere on the stretch.

    The plans' order kept at run time, whatever their timing (an action dependency graph: Hoenig et al. 2019,
    "Persistent and robust execution of MAPF schedules in warehouses"). A robot late on its plan keeps its
    turn where its plan had it first, and one on time waits for it there, instead of taking the room first
    and meeting it head on. Each robot waits only for one planned earlier than itself at the same place, so
    no wait goes round in a cycle while the plans are free of conflicts, with no exception: where the plans
    are not free of conflicts the order can go round, so only the part of a plan that heeded the
    reservations counts (up to `until`: nothing of a plan blind to them). Near: within both radii and `zone`
    (the reservations keep plans farther apart than that, so passages near each other are never at one
    time); compared at the point of the stretch nearest to each point of the other's plan."""
    for other in others:
        if _passes_first(a, b, ta, tb, radius, other, zone):
            return other.label
    return None


def _passes_first(a, b, ta, tb, radius: float, other: Planned, zone: float) -> bool:
    near = radius + other.r + zone
    for p, q in itertools.pairwise([*other.path, other.path[-1]]):  # the last: where it stands, arrived
        if q[2] < other.progress:
            continue
        if p[2] > other.until:
            return False  # beyond what it heeded: no turn of its own from here
        if segment_distance(a, b, p[:2], q[:2]) >= near:
            continue  # a leg far from the stretch: nothing to look at
        n = max(1, math.ceil(math.dist(p[:2], q[:2]) / PRECEDENCE_STEP))
        for i in range(n + 1):
            f = i / n
            point, t = (p[0] + (q[0] - p[0]) * f, p[1] + (q[1] - p[1]) * f), p[2] + (q[2] - p[2]) * f
            if t < other.progress and p[:2] != q[:2]:
                continue  # driven past already (a wait it is in counts: it stands there now)
            if t > other.until:
                return False
            on = nearest_on(point, a, b)
            if math.dist(point, on) < near and t < _time_at(on, a, b, ta, tb):
                return True
    return False


def _time_at(point: Point, a: Point, b: Point, ta: float, tb: float) -> float:
    length = math.dist(a, b)
    return ta if length == 0.0 else ta + (tb - ta) * math.dist(a, point) / length


def wait_cycle(waits: dict[str, str], start: str) -> list[str] | None:
    """The cycle of robots waiting on each other that start is in ({robot: the robot it waits for}); None
    when start's chain of waits ends at a robot that waits for nobody (no deadlock)."""
    seen, robot = [], start
    while robot in waits and robot not in seen:
        seen.append(robot)
        robot = waits[robot]
    if robot == start and seen:
        return seen
    return None


def entry_capsule(pk: int, entry: dict) -> Capsule:
    """The room a claim entry of the traffic table holds ({"a", "b", "r"}), labelled with its robot's id."""
    return Capsule(tuple(entry["a"]), tuple(entry["b"]), entry["r"], str(pk))


def pad(t0: float):
    """Timing slack of a reservation made at t0: half a second, plus PAD_GROWTH of the time ahead. Small: the
    claims keep the plans' order however late or early a robot is (first_to_pass); slack only spaces the
    plans. (A tenth, before the order was kept, made reservations 30 s ahead 7 s wide, and crowds' searches
    failed for lack of room: 33 failed searches in run aw.)"""
    return lambda t: 0.5 + tune.PAD_GROWTH * max(0.0, t - t0)


def passes(path, disc: Capsule, radius: float) -> bool:
    """Whether a path comes within reach of where a robot stands."""
    legs = itertools.pairwise(p[:2] for p in path)
    return any(segment_distance(disc.a, disc.a, a, b) < radius + disc.r + tune.CLAIM_MARGIN for a, b in legs)
