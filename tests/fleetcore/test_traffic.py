"""The plain traffic algorithms: free goal spots, the reservation table, space-time A*, wait-for cycles."""

import itertools
import math

import pytest

from fleetcore import reservations, traffic
from fleetcore.reservations import ReservationTable, cell_of, footprint_cells
from fleetcore.traffic import Capsule, Disc, SpaceTimeSearch

ROOM = (-3.0, 3.0)  # a 6 m x 6 m open room


def open_room(cell):
    x, y = reservations.center_of(cell)
    return ROOM[0] + 0.3 < x < ROOM[1] - 0.3 and ROOM[0] + 0.3 < y < ROOM[1] - 0.3


def conflicts(path, radius, table, robot, pad=0.0):
    """The other robots whose reservations this timed path overlaps (in space and time)."""
    found = set()
    for a, b in itertools.pairwise(path):
        for cells, t0, t1 in reservations.leg_slots(a, b, radius, lambda t: pad):
            who = table.holder(cells, t0, t1, robot)
            if who:
                found.add(who)
    return found


def position(path, t):
    """Where a timed path is at time t (before: its start; after: its end)."""
    if t <= path[0][2]:
        return path[0][:2]
    for (x0, y0, t0), (x1, y1, t1) in itertools.pairwise(path):
        if t0 <= t <= t1:
            f = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
            return x0 + (x1 - x0) * f, y0 + (y1 - y0) * f
    return path[-1][:2]


def closest_approach(a, b, step=0.05):
    """The least distance between two robots following their timed paths."""
    end = max(a[-1][2], b[-1][2])
    return min(math.dist(position(a, i * step), position(b, i * step)) for i in range(int(end / step) + 2))


def search(radius=0.15, speed=0.5, passable=open_room):
    return SpaceTimeSearch(passable, radius, speed, pad=lambda t: 0.3)


def test_a_free_goal_is_kept_and_a_taken_one_moves_to_the_nearest_free_spot():
    anywhere = lambda x, y: True  # noqa: E731
    assert traffic.free_spot((1.0, 1.0), 0.2, [], anywhere) == (1.0, 1.0)
    parked = Disc(1.0, 1.0, 0.3, "robot1")
    spot = traffic.free_spot((1.0, 1.0), 0.2, [parked], anywhere, prefer=(3.0, 1.0))
    gap = math.dist(spot, (1.0, 1.0))
    assert 0.2 + 0.3 + traffic.SPOT_MARGIN <= gap < 0.2 + 0.3 + traffic.SPOT_MARGIN + traffic.SPOT_STEP + 1e-9
    assert spot[0] > 1.0 and traffic.compass((1.0, 1.0), spot) == "east"  # on the side it comes from


def test_a_free_spot_keeps_clear_of_the_whole_stretch_a_robot_holds_not_only_where_it_began():
    """A robot holding a stretch of its way (a claim, a to b) takes all of it: a goal at the stretch's far end
    is taken, and the spot given instead is clear of the segment (a disc at `a` alone had called the goal
    free, and a spot beside the stretch's middle free too)."""
    anywhere = lambda x, y: True  # noqa: E731
    holding = Capsule((0.0, 0.0), (2.0, 0.0), 0.3, "tiago")
    assert traffic.clear_of((2.0, 0.0), 0.2, [holding]) is holding
    assert traffic.clear_of((1.0, 0.6), 0.2, [holding]) is holding  # beside the middle
    spot = traffic.free_spot((2.0, 0.0), 0.2, [holding], anywhere, prefer=(1.0, 3.0))
    assert holding.distance(spot) >= 0.2 + 0.3 + traffic.SPOT_MARGIN - 1e-9, spot
    assert Disc(0.0, 0.0, 0.3).distance(spot) > holding.distance(
        spot
    )  # the stretch, not its first end, decided


def test_a_free_spot_stands_on_free_ground():
    east_is_wall = lambda x, y: x < 1.2  # noqa: E731
    spot = traffic.free_spot((1.0, 1.0), 0.2, [Disc(1.0, 1.0, 0.3)], east_is_wall, prefer=(3.0, 1.0))
    assert spot[0] < 1.2 and traffic.clear_of(spot, 0.2, [Disc(1.0, 1.0, 0.3)]) is None
    nowhere = lambda x, y: False  # noqa: E731
    assert traffic.free_spot((1.0, 1.0), 0.2, [], nowhere) is None


def test_a_lone_robot_drives_straight_to_its_goal():
    path = search().plan((-2.0, 0.1), (2.0, 0.1), 100.0, ReservationTable(), "a")
    assert [p[:2] for p in path] == [(-2.0, 0.1), (2.0, 0.1)]
    assert path[-1][2] == pytest.approx(100.0 + 4.0 / 0.5, abs=0.5)


def test_a_crossing_robot_waits_or_detours_around_a_reserved_path():
    table = ReservationTable()
    first = search().plan((-2.0, 0.1), (2.0, 0.1), 0.0, table, "a")
    table.reserve_path("a", first, 0.15, lambda t: 0.3)
    second = search().plan((0.1, -2.0), (0.1, 2.0), 0.0, table, "b")  # straight across a's line, same time
    assert second is not None and second[-1][:2] == (0.1, 2.0)
    assert conflicts(second, 0.15, table, "b", pad=0.3) == set()
    straight_time = 4.0 / 0.5
    assert second[-1][2] > straight_time  # it paid with a wait or a detour, not with a collision


def test_two_pairs_swapping_places_find_plans_with_no_overlap():
    """Prioritized planning: each robot plans against the paths reserved before it and the goals where those
    robots will stand (from their arrival on); then no two plans meet, in space and time."""
    table, plans, parked = ReservationTable(), {}, []
    tasks = {
        "a": ((-2.0, 0.1), (2.0, 0.1)),
        "b": ((2.0, 0.1), (-2.0, 0.1)),
        "c": ((0.1, -2.0), (0.1, 2.0)),
        "d": ((0.1, 2.0), (0.1, -2.0)),
    }
    for robot, (start, _) in tasks.items():
        table.reserve(robot, footprint_cells(start, 0.15), 0.0, 1.0)  # standing at its start now
    for robot, (start, goal) in tasks.items():
        table.release(robot)
        plans[robot] = search().plan(start, goal, 0.0, table, robot, parked)
        assert plans[robot] is not None, robot
        table.reserve_path(robot, plans[robot], 0.15, lambda t: 0.3)
        parked.append((Capsule(goal, goal, 0.15, robot), plans[robot][-1][2]))
    for a, b in itertools.combinations(plans, 2):
        assert closest_approach(plans[a], plans[b]) > 0.3, (a, b)  # two radii: their discs never overlap


def test_a_robot_standing_is_gone_round_and_a_robot_parked_close_may_leave():
    standing = [(Capsule((0.1, 0.1), (0.1, 0.1), 0.3, "parked"), -math.inf)]
    path = search().plan((-2.0, 0.1), (2.0, 0.1), 0.0, ReservationTable(), "a", standing)
    assert closest_approach(path, [(0.1, 0.1, 0.0)]) >= 0.3 + 0.15 - reservations.TRAFFIC_CELL / 2
    squeezed = search().plan(
        (0.1, 0.45), (0.1, 2.0), 0.0, ReservationTable(), "b", standing
    )  # starts too close
    assert squeezed is not None and squeezed[-1][:2] == (0.1, 2.0)


def test_nobody_parks_where_another_robot_will_pass():
    table = ReservationTable()
    goal = (0.1, 0.1)
    table.reserve("a", footprint_cells(goal, 0.15), 20.0, 25.0)  # a passes the goal at t = 20..25
    path = search().plan((-2.0, 0.1), goal, 0.0, table, "b")
    assert path is not None
    assert path[-1][2] >= 25.0  # b arrives after a has passed (alone it would be there by t = 5)


def test_reservations_far_ahead_are_heeded_all_the_way():
    """No window: what another robot reserved long after now still holds a plan up (a plan blind to the
    others beyond a window let the order kept at run time go round), and is waited out in one state."""
    table = ReservationTable()
    goal = (0.1, 0.1)
    table.reserve("a", footprint_cells(goal, 0.15), 35.0, 40.0)  # a passes the goal at t = 35..40
    found = search()
    path = found.plan((-2.0, 0.1), goal, 0.0, table, "b")
    assert path is not None and path[-1][2] >= 40.0  # not there by t = 5 to stand in a's way at 35
    assert found.expanded < 5_000  # (a wait is one state: stepping through time took one per tick and cell)


def test_busy_intervals_agree_with_the_table():
    table = ReservationTable()
    table.reserve("a", [(0, 0)], 1.0, 2.0)
    table.reserve("b", [(0, 0)], 1.5, 3.0)
    table.reserve("c", [(0, 0)], 5.0, 6.0)
    table.reserve("me", [(1, 1)], 0.0, 9.0)
    busy = table.intervals("me")
    for lo, hi in [(0.0, 1.0), (0.0, 1.1), (2.5, 2.9), (3.0, 5.0), (3.1, 4.9), (5.5, 9.0), (6.0, 7.0)]:
        expected = table.holder([(0, 0)], lo, hi, "me") is not None
        assert busy.union([(0, 0)]).overlaps(lo, hi) is expected, (lo, hi)
    assert not busy.union([(1, 1)]).overlaps(0.0, 9.0)  # its own reservations never hold it up
    table.reserve("d", [(2, 2)], 2.5, 4.0)
    either = table.intervals("me").union([(0, 0), (2, 2), (1, 1)])
    assert (either.starts, either.ends) == ([1.0, 5.0], [4.0, 6.0])  # one footprint: one look-up


def test_an_unreachable_goal_has_no_plan():
    walled = lambda c: open_room(c) and not (0.0 <= reservations.center_of(c)[0] <= 0.4)  # noqa: E731
    assert search(passable=walled).plan((-2.0, 0.1), (2.0, 0.1), 0.0, ReservationTable(), "a") is None


def test_wait_cycles_are_found_and_chains_are_not():
    assert traffic.wait_cycle({"a": "b", "b": "a"}, "a") == ["a", "b"]
    assert traffic.wait_cycle({"a": "b", "b": "c", "c": "a", "d": "a"}, "c") == ["c", "a", "b"]
    assert (
        traffic.wait_cycle({"a": "b", "b": "c"}, "a") is None
    )  # c waits for nobody: a chain, not a deadlock
    assert traffic.wait_cycle({"d": "a", "a": "b", "b": "a"}, "d") is None  # d waits on a cycle it is not in


def test_cells_cover_the_footprint():
    cells = footprint_cells((0.1, 0.1), 0.25)
    assert cell_of((0.1, 0.1)) in cells and cell_of((0.33, 0.1)) in cells and cell_of((0.6, 0.1)) not in cells


def test_a_goal_robots_standing_wall_off_fails_at_once_and_one_they_will_only_later_does_not():
    wall = [(Capsule((0.2, y), (0.2, y), 0.3, f"parked{i}"), -math.inf) for i, y in enumerate((-2.4, -1.8, -1.2,
            -0.6, 0.0, 0.6, 1.2, 1.8, 2.4))]  # fmt: skip
    walled = search()
    assert walled.plan((-2.0, 0.1), (2.0, 0.1), 0.0, ReservationTable(), "a", wall) is None
    assert walled.expanded == 0  # not a state spent on waiting for a way that never opens
    later = [(capsule, 30.0) for capsule, _ in wall]  # they will stand there from t = 30: it passes before
    path = search().plan((-2.0, 0.1), (2.0, 0.1), 0.0, ReservationTable(), "a", later)
    assert path is not None and path[-1][:2] == (2.0, 0.1) and path[-1][2] < 30.0


def test_a_wait_of_any_length_is_one_state_at_any_speed():
    """Safe intervals: a robot waiting 30 s or 200 s for the way to open spends no more states on it than there
    are cells on its side of the way, slow or fast (a Husky's tick is 0.1 s). Stepping through time, a fast
    robot spent 97,000 states on a 30 s wait; in a crowd such searches ran out of states and the robot drove a
    plan blind to the reservations."""
    corridor = lambda c: 0 <= c[0] < 50 and 0 <= c[1] < 15  # noqa: E731  # 10 m x 3 m, 750 cells
    expanded = {}
    for speed in (0.4, 2.0):
        for blocked in (30.0, 200.0):
            table = ReservationTable()  # another robot across the corridor, at x = 5 m, for `blocked` s
            table.reserve("other", reservations.swept_cells((5.0, 0.0), (5.0, 3.0), 0.3), 0.0, blocked)
            search = SpaceTimeSearch(corridor, 0.2, speed, pad=lambda t: 0.5, max_expansions=10**6)
            path = search.plan((0.5, 1.5), (9.5, 1.5), 0.0, table, "me")
            assert path is not None and path[-1][:2] == (9.5, 1.5)
            assert path[-1][2] > blocked  # it waited for the way to open...
            assert not conflicts(path, 0.2, table, "me")  # ... and passed after it had
            expanded[speed, blocked] = search.expanded
    assert all(expanded[speed, 30.0] == expanded[speed, 200.0] < 750 for speed in (0.4, 2.0)), expanded


def stretches_of(path, longest=1.2):
    """A timed path cut into stretches of at most `longest` metres: [(a, b, ta, tb), ...] (waits left out)."""
    out = []
    for p, q in itertools.pairwise(path):
        n = max(1, math.ceil(math.dist(p[:2], q[:2]) / longest))
        for i in range(n):
            f0, f1 = i / n, (i + 1) / n
            a = (p[0] + (q[0] - p[0]) * f0, p[1] + (q[1] - p[1]) * f0)
            b = (p[0] + (q[0] - p[0]) * f1, p[1] + (q[1] - p[1]) * f1)
            if a != b:
                out.append((a, b, p[2] + (q[2] - p[2]) * f0, p[2] + (q[2] - p[2]) * f1))
    return out


def test_a_robot_late_on_its_plan_keeps_its_turn_where_its_plan_had_it_first():
    """o's plan crosses x = 0 at t = 2, r's at t = 3 (after o). o is late: it has not set off at all. r, on time,
    lets it pass first at the crossing; once o holds a stretch beyond it, r goes."""
    o_path = [(-2.0, 0.0, 0.0), (2.0, 0.0, 4.0)]
    crossing = ((0.0, -1.0), (0.0, 1.0), 2.0, 4.0)  # r's stretch: at the crossing at t = 3
    late = traffic.Planned("o", o_path, 0.2, progress=0.0)
    assert traffic.first_to_pass(*crossing, 0.2, [late]) == "o"
    past = traffic.Planned("o", o_path, 0.2, progress=3.0)  # o's stretch now begins at x = 1: it has passed
    assert traffic.first_to_pass(*crossing, 0.2, [past]) is None
    before = ((0.0, -1.0), (0.0, 1.0), 0.0, 2.0)  # r planned at the crossing at t = 1, before o
    assert traffic.first_to_pass(*before, 0.2, [late]) is None  # r goes first: o will wait for it
    assert traffic.first_to_pass((0.0, -3.0), (0.0, -2.0), 2.0, 4.0, 0.2, [late]) is None  # nowhere near


def test_a_plan_counts_for_the_order_only_where_it_heeded_the_others_and_within_its_zone():
    """o planned blind beyond t = 1 (no plan heeding the reservations) has no turn at the crossing it reaches
    at t = 2. o passing 0.55 m beside r's stretch, beyond both radii (0.4 m), is not near it; within a zone
    of 0.2 m more it is, and r lets it pass first: the zone is wider than the claims' margin, so a robot
    that would come too near for a claim is ordered, and narrower than the plans' spacing, so no two
    passages within it are ever at one time."""
    crossing = ((0.0, -1.0), (0.0, 1.0), 2.0, 4.0)
    blind = traffic.Planned("o", [(-2.0, 0.0, 0.0), (2.0, 0.0, 4.0)], 0.2, progress=0.0, until=1.0)
    assert traffic.first_to_pass(*crossing, 0.2, [blind]) is None
    beside = traffic.Planned("o", [(0.55, -2.0, 0.0), (0.55, 2.0, 4.0)], 0.2, progress=0.0)
    assert traffic.first_to_pass(*crossing, 0.2, [beside]) is None
    assert traffic.first_to_pass(*crossing, 0.2, [beside], zone=0.2) == "o"
    through = traffic.Planned("o", [(-2.0, -1.0, 0.0), (0.0, -1.0, 2.0), (0.0, 1.0, 2.5)], 0.2, 0.0)
    assert traffic.first_to_pass(*crossing, 0.2, [through]) == "o"  # no exception where r stands


def test_the_cells_of_a_robot_off_its_cells_centre_cover_every_point_of_its_disc():
    """A robot near a corner of its cell: every point of its disc lies in a cell counted (taken as a disc at
    the cell's centre, points up to 0.14 m beyond were missed, and plans passed nearer than their radii)."""
    for point in [(0.01, 0.01), (0.19, 0.02), (0.11, 0.18), (-0.37, 0.55)]:
        cells = footprint_cells(point, 0.3)
        rim = [
            (point[0] + 0.2999 * math.cos(a), point[1] + 0.2999 * math.sin(a))
            for a in (i * math.tau / 360 for i in range(360))
        ]
        assert all(cell_of(p) in cells for p in rim), point
        assert (
            len(cells) <= 25
        )  # and no more than the cells it reaches (a 3 x 3 block and parts of a 5 x 5 one)


def test_no_two_robots_on_conflict_free_plans_each_wait_for_the_other_to_pass_first():
    """The plans' order as the claims keep it: for two pairs swapping places (prioritized plans), whatever
    stretch each robot has reached, never does each wait for the other (first_to_pass), which would be a
    deadlock; and some robot does wait for another somewhere (the plans do cross)."""
    table, plans, parked = ReservationTable(), {}, []
    tasks = {
        "a": ((-2.0, 0.1), (2.0, 0.1)),
        "b": ((2.0, 0.1), (-2.0, 0.1)),
        "c": ((0.1, -2.0), (0.1, 2.0)),
        "d": ((0.1, 2.0), (0.1, -2.0)),
    }
    for robot, (start, goal) in tasks.items():
        plans[robot] = search().plan(start, goal, 0.0, table, robot, parked)
        table.reserve_path(robot, plans[robot], 0.15, lambda t: 0.3)
        parked.append((Capsule(goal, goal, 0.15, robot), plans[robot][-1][2]))
    waits = 0
    for r, o in itertools.permutations(plans, 2):
        for a, b, ta, tb in stretches_of(plans[r]):
            for oa, ob, ota, otb in stretches_of(plans[o]):
                r_waits = traffic.first_to_pass(a, b, ta, tb, 0.15, [traffic.Planned(o, plans[o], 0.15, ota)])
                o_waits = traffic.first_to_pass(
                    oa, ob, ota, otb, 0.15, [traffic.Planned(r, plans[r], 0.15, ta)]
                )
                assert not (r_waits and o_waits), (r, (a, b, ta, tb), o, (oa, ob, ota, otb))
                waits += bool(r_waits)
    assert waits > 0
