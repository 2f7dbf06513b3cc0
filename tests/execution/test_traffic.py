"""The traffic table in Redis: reservations, claims, waits and deadlocks (no simulator; the robots are rows)."""

import asyncio
import itertools
import math
import time
import types

import pytest

import live
from execution import coordination, driving, make_way, route, traffic, traffic_fleet, traffic_state
from execution.steps import StepFailed
from fleetcore import motion
from fleetcore import traffic as plain
from fleetcore import traffic_tuning as tune
from places.worlds import load_world_into_db
from robots.models import Robot
from robots.poses import forget_poses, store_poses
from tests.fleetcore.test_traffic import position

SQUARE = [[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]]


@pytest.fixture
def robots(transactional_db, exec_settings):
    """Three small robots on the paper map, standing apart (their poses in the pose store). Committed: the
    steps' database calls run on the executor's blocking pool, in threads of their own."""
    load_world_into_db("paper")
    made = {}
    for name, (x, y) in {"a": (-2.0, 0.0), "b": (0.0, -2.0), "c": (4.0, 4.0)}.items():
        robot = Robot.objects.create(name=name, endpoint=f"ws://sim/{name}", footprint=SQUARE)
        store_poses([{"id": robot.pk, "x": x, "y": y, "yaw": 0.0}])
        made[name] = robot
    yield made
    forget_poses([r.pk for r in made.values()])


def plan(robot, start, goal, speed, **options):
    """traffic.plan (a step's, on the executor's loop) from a test: on a loop of its own."""
    return asyncio.run(traffic.plan(robot, start, goal, speed, **options))


def test_a_claimed_stretch_is_refused_to_a_robot_crossing_it_until_released(robots):
    a, b = robots["a"], robots["b"]
    assert traffic.claim(a, (-2.0, 0.0), (2.0, 0.0)) is None
    assert traffic.claim(b, (0.0, -2.0), (0.0, 2.0)) == a.pk  # across a's stretch: a is in the way
    assert traffic.claim(b, (0.0, -2.0), (0.0, -1.0)) is None  # short of it: free
    traffic_state.release(a, (2.0, 0.0, 0.0))  # a has arrived and parks at (2, 0)
    assert traffic.claim(b, (0.0, -1.0), (0.0, 2.0)) is None
    assert traffic.claim(b, (0.0, 2.0), (2.0, 0.3)) == a.pk  # onto where a parked
    assert traffic.claim(b, (0.0, 2.0), (-1.0, 3.0)) is None  # and away from it


def test_a_robot_on_time_lets_one_late_on_its_plan_pass_first_where_that_one_was_planned_first(robots):
    """a's plan crosses x = 0 at now + 2 s, b's crosses y = 0 at now + 4 s. a is held up, still at its start;
    b, on time, is refused its stretch across a's way (a goes first there, as planned). Once a holds a
    stretch past the crossing, b gets it; a robot whose step ended (released) holds nobody up by its plan."""
    a, b = robots["a"], robots["b"]
    redis, now = coordination.connection(), time.time()
    traffic_state.reserve(
        redis, a, [(-2.0, 0.0, now), (2.0, 0.0, now + 4.0)], traffic_fleet.reach(a), now, 30.0
    )
    traffic_state.reserve(
        redis, b, [(0.0, -2.0, now), (0.0, 2.0, now + 8.0)], traffic_fleet.reach(b), now, 30.0
    )
    assert traffic.claim(a, (-2.0, 0.0), (-2.0, 0.0), planned=(now, now)) is None  # a stands, late
    across = ((0.0, -1.0), (0.0, 1.0))
    assert traffic.claim(b, *across, planned=(now + 3.0, now + 5.0)) == a.pk
    assert traffic.claim(b, (0.0, -2.0), (0.0, -1.5), planned=(now, now + 1.0)) is None  # short of it: free
    assert traffic.claim(a, (1.0, 0.0), (2.0, 0.0), planned=(now + 3.0, now + 4.0)) is None
    assert traffic.claim(b, *across, planned=(now + 3.0, now + 5.0)) is None
    assert traffic.claim(b, (0.0, -1.5), (0.0, -1.5), planned=(now + 1.0, now + 1.0)) is None  # b back
    traffic.claim(a, (-2.0, 0.0), (-2.0, 0.0), planned=(now, now))  # (a, as late as before)
    traffic_state.release(a, None)
    assert traffic.claim(b, *across, planned=(now + 3.0, now + 5.0)) is None


def test_a_plan_goes_around_the_path_reserved_before_it(robots):
    a, b = robots["a"], robots["b"]
    first = plan(a, (-2.0, 0.0), (2.0, 0.0), 0.3)
    second = plan(b, (0.0, -2.0), (0.0, 2.0), 0.3)
    assert second[-1][:2] == (0.0, 2.0) and first[-1][:2] == (2.0, 0.0)
    table = plain.ReservationTable()
    table.reserve_path("a", first, traffic_fleet.reach(a), lambda t: 0.0)
    crossing = [
        table.holder(cells, t0, t1, "b")
        for p, q in itertools.pairwise(second)
        for cells, t0, t1 in plain.leg_slots(p, q, traffic_fleet.reach(b), lambda t: 0.0)
    ]
    assert not any(crossing)  # b passes where a is not, when it passes
    assert (
        second[-1][2] - second[0][2] > 4.0 / 0.3 - 1e-6
    )  # it waited or went round: not faster than straight


def test_a_wait_for_cycle_is_broken_by_the_robot_that_gave_way_least_then_the_highest_id(robots):
    a, b = robots["a"], robots["b"]
    redis = coordination.connection()
    before = traffic_state.deadlocks()
    traffic_state.write(redis, "waits", a.pk, {"for": b.pk, "expires": 1e12})
    traffic._check_deadlock(redis, a.pk)  # a waits for b, b for nobody: a chain, no deadlock
    traffic_state.write(redis, "waits", b.pk, {"for": a.pk, "expires": 1e12})
    low, high = sorted((a, b), key=lambda r: r.pk)
    traffic._check_deadlock(redis, low.pk)  # the lower id keeps waiting
    with pytest.raises(traffic.Reroute) as caught:
        traffic._check_deadlock(redis, high.pk)
    assert caught.value.around == {low.pk} and caught.value.gave_way  # (counted apart from going round)
    assert traffic_state.deadlocks() == before + 1
    traffic._check_deadlock(redis, low.pk)  # broken once: the breaker waits no more, low keeps waiting
    assert traffic_state.deadlocks() == before + 1
    # the same two wait for each other again (the reroute did not get high out of low's way): low gives way
    traffic_state.write(redis, "waits", high.pk, {"for": low.pk, "expires": 1e12})
    traffic._check_deadlock(redis, high.pk)
    with pytest.raises(traffic.Reroute) as caught:
        traffic._check_deadlock(redis, low.pk)
    assert caught.value.around == {high.pk}
    assert traffic_state.deadlocks() == before + 2


def test_a_waiting_robot_notes_the_stretch_it_waits_to_drive_and_a_deadlock_log_gives_each(
    robots, monkeypatch, caplog
):
    """What a deadlock's log line says of each robot of the cycle: whom it waits for, why, and the stretch it
    waits to drive (how the face-to-face cycles of runs bd and after were told apart)."""
    a, b = robots["a"], robots["b"]
    monkeypatch.setattr(tune, "WAIT_LIMIT_S", 0.3)
    assert traffic.claim(b, (0.0, -2.0), (0.0, 2.0)) is None  # b holds a stretch across a's way
    with pytest.raises(StepFailed):
        asyncio.run(traffic.wait_for(StandingSession(a, (-2.0, 0.0, 0.0)), (-2.0, 0.0), (2.0, 0.0)))
    redis = coordination.connection()
    wait = traffic_state.read(redis, "waits")[a.pk]
    assert (wait["for"], wait["why"], wait["to"]) == (b.pk, "room", [[-2.0, 0.0], [2.0, 0.0]])
    across = {"for": a.pk, "why": "room", "to": [[0.0, -2.0], [0.0, 2.0]], "expires": 1e12}
    traffic_state.write(redis, "waits", b.pk, across)  # and b waits for a: a cycle
    caplog.set_level("INFO", logger="execution.traffic")
    with pytest.raises(traffic.Reroute):
        for robot in sorted((a, b), key=lambda r: r.pk):  # the higher id breaks it
            traffic._check_deadlock(redis, robot.pk)
    line = next(r.getMessage() for r in caplog.records if "deadlock among" in r.getMessage())
    assert "('room', [[-2.0, 0.0], [2.0, 0.0]])" in line and "('room', [[0.0, -2.0], [0.0, 2.0]])" in line


def test_the_map_is_told_the_route_and_whom_a_robot_waits_for(robots, monkeypatch):
    sent = []
    monkeypatch.setattr(live, "send_on_commit", lambda group, payload: sent.append((group, payload)))
    live.path(robots["a"], [(1.0, 2.0), (3.0, 4.0)], None)
    live.path(robots["a"], None, "b")
    payloads = [payload for group, payload in sent if group == live.FLEET_GROUP]
    assert payloads[0] == {
        "type": "robot.path",
        "id": robots["a"].pk,
        "robot": "a",
        "path": [[1.0, 2.0], [3.0, 4.0]],
        "waiting_for": None,
    }
    assert payloads[1]["path"] is None and payloads[1]["waiting_for"] == "b"


def test_a_map_that_opens_now_gets_the_reserved_routes_and_the_waits(robots):
    from portal.snapshots import robot_rows

    a, b, c = robots["a"], robots["b"], robots["c"]
    plan(a, (-2.0, 0.0), (2.0, 0.0), 0.3)
    traffic_state.write(coordination.connection(), "waits", b.pk, {"for": a.pk, "expires": 1e12})
    rows = {row["name"]: row for row in robot_rows([a, b, c])}
    route = rows["a"]["route"]
    assert route[0] == [-2.0, 0.0] and route[-1] == [2.0, 0.0] and len(route) <= tune.MAP_POINTS + 2
    assert rows["a"]["waiting_for"] is None and rows["b"]["waiting_for"] == "a"
    assert "route" not in rows["c"]  # not under traffic
    assert robot_rows([b])[0]["waiting_for"] == "a"  # named though not among the rows
    traffic_state.release(a, (2.0, 0.0, 0.0))
    coordination.connection().hdel(traffic_state.key("waits"), str(b.pk))
    assert "route" not in robot_rows([a])[0]


def test_stretches_are_short_and_keep_the_planned_waits():
    path = [(0.0, 0.0, 0.0), (3.0, 0.0, 10.0), (3.0, 0.0, 12.0), (3.0, 1.0, 15.0)]
    legs = driving.stretches(path)
    assert all(
        math.dist(p[:2], q[:2]) <= tune.LEG_M + 1e-9 for p, q in zip([path[0], *legs], legs, strict=False)
    )
    assert [leg[3] for leg in legs].count(True) == 1 and legs[-1][:2] == (3.0, 1.0)


def _slots_on(path, radius: float, cells: set, t0: float, t1: float) -> list:
    """The slots of a timed path that touch these cells within [t0, t1] (no padding)."""
    return [
        (p, q)
        for p, q in itertools.pairwise(path)
        for slot, a, b in plain.leg_slots(p, q, radius, lambda t: 0.0)
        if slot & cells and a < t1 and t0 < b
    ]


def test_a_robot_that_has_not_planned_yet_is_gone_round_as_standing_for_good(robots):
    """b stands on a's line, under traffic, with no plan yet (it waits for its turn): a's plan keeps clear of
    where b stands for as long as it runs, not only for a while. (A plan passing there later, once b should
    have left, made b's own plan wait on its start for a to pass, and the order went round.)"""
    a, b = robots["a"], robots["b"]
    assert traffic.claim(b, (0.0, -2.0), (0.0, -2.0)) is None
    path = plan(a, (-4.0, -2.0), (4.0, -2.0), 0.5)
    assert path[-1][:2] == (4.0, -2.0)
    closest = min(
        plain.segment_distance((0.0, -2.0), (0.0, -2.0), p[:2], q[:2]) for p, q in itertools.pairwise(path)
    )
    assert closest >= traffic_fleet.reach(a) + traffic_fleet.reach(b)


def test_when_the_reservations_leave_no_plan_the_robot_has_none_and_reserves_nothing(robots):
    """c's plan holds a's goal from a second on for 1,000 s, longer than any search looks ahead: a gets no
    plan (its travel stands and plans again), not a plan blind to the others (every deadlock of a run
    followed one such plan), and nothing of it is reserved."""
    a, c = robots["a"], robots["c"]
    redis, now = coordination.connection(), time.time()
    goal_cells = plain.footprint_cells((4.0, -2.0), traffic_fleet.reach(a) + 0.2)
    entry = {
        "cells": [[col, row, now + 1.0, now + 1000.0] for col, row in goal_cells],
        "goal": [4.0, 4.0],
        "r": traffic_fleet.reach(c),
        "at": now + 1000.0,
        "expires": now + 2000.0,
    }
    traffic_state.write(redis, "plans", c.pk, entry)
    assert plan(a, (-4.0, -2.0), (4.0, -2.0), 0.5) is None
    assert a.pk not in traffic_state.read(redis, "plans") and a.pk not in traffic_state.read(redis, "timed")
    traffic_state.release(c, None)
    assert plan(a, (-4.0, -2.0), (4.0, -2.0), 0.5)[-1][:2] == (4.0, -2.0)  # once it has gone


def test_plans_keep_more_room_between_robots_than_the_claims_ask(robots):
    """b drives west 0.55 m beside a's way east, head on: where both are at one time they keep both reaches
    and SPACING_M on each side apart (0.79 m here; with no spacing the plans passed 0.53 m apart, 0.15 m
    more than both reaches, where a robot 0.1 m off its line is refused its claim), so robots off their
    plans' lines still get their claims where their plans pass each other."""
    a, b = robots["a"], robots["b"]
    first = plan(a, (-4.0, -2.0), (4.0, -2.0), 0.5)
    second = plan(b, (4.0, -1.45), (-4.0, -1.45), 0.5)
    end = max(first[-1][2], second[-1][2])
    times = [first[0][2] + i * 0.05 for i in range(int((end - first[0][2]) / 0.05))]
    closest = min(math.dist(position(first, t), position(second, t)) for t in times)
    assert closest >= traffic_fleet.reach(a) + traffic_fleet.reach(b) + 2 * tune.SPACING_M


def test_a_goal_kept_from_an_earlier_plan_next_to_a_robot_standing_is_reached_by_a_search(robots, caplog):
    a, b = robots["a"], robots["b"]  # b stands at (0, -2)
    near_b = (
        0.0,
        -2.0 + traffic_fleet.reach(a) + traffic_fleet.reach(b) + tune.CLAIM_MARGIN + 0.03,
    )  # inside the margins
    with caplog.at_level("INFO", logger="execution.traffic"):
        path = plan(a, (-2.0, 0.0), near_b, 0.5, settled=True)  # kept: nobody would touch it there
    assert path[-1][:2] == pytest.approx(near_b)
    assert "no conflict-free plan" not in caplog.text and "found no plan" not in caplog.text, caplog.text


def test_a_plan_to_a_goal_next_to_a_robot_standing_goes_round_it_as_far_as_the_claims_ask(robots):
    """A settled goal just west of b, reached from the east: the plan goes round b no nearer than the claims
    let it, so each of its stretches is granted (planned round b at b's bare size, it passed 0.04 m too near:
    refused there, rerouted and planned the same, four times, and the step failed: run av)."""
    a, b = robots["a"], robots["b"]  # b stands at (0, -2)
    west_of_b = (-(traffic_fleet.reach(a) + traffic_fleet.reach(b) + tune.CLAIM_MARGIN + 0.03), -2.0)
    path = plan(a, (2.0, -2.0), west_of_b, 0.5, settled=True)
    assert path[-1][:2] == pytest.approx(west_of_b)
    here = (2.0, -2.0)
    for x, y, _, hold in driving.stretches(path):
        if not hold:
            assert traffic.claim(a, here, (x, y)) is None, (here, (x, y))
            here = (x, y)


def test_a_corner_is_driven_to_closely_and_a_point_on_a_straight_way_loosely():
    round_the_shelf = [(8.8, 9.0, 0.0, False), (8.8, 11.2, 1.0, False), (6.0, 11.6, 2.0, False)]
    along_the_shelf = [(8.8, 9.0, 0.0, False), (8.8, 10.0, 1.0, False), (8.8, 11.0, 2.0, False)]
    slight_bend = [(14.0, 2.0, 0.0, False), (14.0, 4.0, 1.0, False), (14.5, 6.0, 2.0, False)]
    assert driving._tolerance((8.8, 8.0), round_the_shelf, 1) == tune.CORNER_TOLERANCE
    assert driving._tolerance((8.8, 8.0), along_the_shelf, 1) == tune.WAYPOINT_TOLERANCE
    assert driving._tolerance((14.0, 1.0), slight_bend, 1) == tune.WAYPOINT_TOLERANCE  # 14 degrees
    assert driving._tolerance((8.8, 8.0), round_the_shelf, 0) == tune.WAYPOINT_TOLERANCE  # from the pose
    assert tune.CORNER_TOLERANCE <= motion.TOLERANCE / 2


def test_a_robot_giving_way_backs_straight_off_else_aside_and_never_into_a_shelf():
    from fleetcore.planning import Planner
    from fleetcore.world import load_world

    planner = Planner(load_world("warehouse").map, 0.15)
    nose_to_nose = [plain.Capsule((14.45, 3.0), (14.45, 3.0), 0.2, "other")]
    first = driving.give_way((14.0, 3.0), nose_to_nose, planner)[0]
    assert first == pytest.approx((14.0 - tune.BACK_OFF_M, 3.0))  # straight away from the other
    # against a shelf's east face (x 8.5): straight away is into it; it goes aside, never nearer the other
    by_the_shelf = [plain.Capsule((9.2, 9.0), (9.2, 9.0), 0.2, "other")]
    targets = driving.give_way((8.8, 9.0), by_the_shelf, planner)
    assert targets and all(planner.free(*planner.to_cell(*t)) for t in targets)
    assert all(math.dist(t, (9.2, 9.0)) > 0.4 for t in targets)
    assert driving.give_way((1.0, 1.0), [], planner) == []
    assert plain.nearest_on((1.0, 1.0), (0.0, 0.0), (2.0, 0.0)) == (1.0, 0.0)
    assert plain.nearest_on((3.0, 1.0), (0.0, 0.0), (2.0, 0.0)) == (2.0, 0.0)


def test_a_trip_goes_where_the_robot_can_turn_and_only_near_its_ends_where_it_can_just_pass(
    transactional_db, exec_settings
):
    load_world_into_db("warehouse")
    husky = [[-0.495, -0.285], [-0.495, 0.285], [0.495, 0.285], [0.495, -0.285]]
    robot = Robot.objects.create(name="husky", endpoint="ws://sim/husky", footprint=husky)
    turning = route.planner_for(robot, turning=True)
    assert turning.radius == pytest.approx(math.hypot(0.495, 0.285), abs=0.01)
    assert route.planner_for(robot).radius == pytest.approx(0.285, abs=0.01)
    by_the_rack = (3.05, 8.75)  # 0.45 m from a rack's face: it can stand there, not turn there
    planner, passable = traffic.trip_ground(robot, (1.2, 5.0), (14.0, 14.0))
    assert planner.free(*planner.to_cell(*by_the_rack)) and not passable(plain.cell_of(by_the_rack))
    _, passable = traffic.trip_ground(robot, (1.2, 5.0), by_the_rack)
    assert passable(plain.cell_of(by_the_rack))  # near its goal: room to pass will do
    path = plan(robot, (1.2, 5.0), by_the_rack, 0.5)
    assert path[-1][:2] == by_the_rack
    path = plan(robot, (1.2, 5.0), (14.0, 14.0), 0.5)  # north, through an aisle, round racks' corners
    assert path[-1][:2] == (14.0, 14.0)
    corners = [p[:2] for p in path[1:-1]]  # where it turns on the spot
    assert corners and all(turning.free(*turning.to_cell(*p)) for p in corners), corners


def test_a_robot_making_way_stands_clear_of_the_route_it_makes_way_for_as_near_as_it_can(robots):
    b = robots["b"]
    request = {"for": robots["a"].pk, "r": 0.5, "route": [[-4.0, -2.0], [4.0, -2.0]]}
    spot = make_way.aside(b, (0.0, -2.0), request)
    clear = 0.5 + traffic_fleet.reach(b) + tune.CLAIM_MARGIN + tune.PLAN_MARGIN
    assert spot is not None and clear <= abs(spot[1] + 2.0) <= clear + 2 * tune.ASIDE_STEP, spot
    planner = route.planner_for(b)
    assert planner.free(*planner.to_cell(*spot))


def test_only_idle_robots_on_the_route_are_asked_to_make_way_and_one_asked_is_waited_for(robots):
    a, b, c = robots["a"], robots["b"], robots["c"]
    redis = coordination.connection()
    _, still = traffic.obstacles(redis, a.pk, time.time())
    through = [(-4.0, -2.0), (4.0, -2.0)]  # b stands on it, c far from it
    assert set(traffic._idle_in_the_way(redis, a, through, still)) == {b.pk}
    assert traffic.claim(b, (0.0, -2.0), (0.0, -2.0)) is None  # b under traffic now: not idle
    assert traffic._idle_in_the_way(redis, a, through, still) == {}
    traffic_state.release(b, (0.0, -2.0, 0.0))
    assert traffic._parked(redis, b.pk, waited=5.0)  # parked, not asked: go round it
    traffic_state.write(redis, "makeway", b.pk, {"for": a.pk, "sent": True, "refused": "", "expires": 1e12})
    assert not traffic._parked(redis, b.pk, waited=5.0)  # asked: it will make way, wait for it
    assert traffic._idle_in_the_way(redis, c, through, still) == {}  # and nobody else asks it meanwhile
    traffic_state.made_way(b, "no free spot off a's way")  # it could not: go round it after all
    assert traffic._parked(redis, b.pk, waited=5.0)
    traffic_state.made_way(b)  # back where it was: asked no more, not by a again on this trip
    assert traffic_state.way_request(b) is None
    assert traffic._parked(redis, b.pk, waited=5.0)
    assert traffic._idle_in_the_way(redis, a, through, still) == {}
    assert set(traffic._idle_in_the_way(redis, c, through, still)) == {b.pk}  # another robot may ask it


def test_a_robot_that_made_way_is_not_asked_again_by_the_same_robot(robots):
    a, b = robots["a"], robots["b"]
    redis = coordination.connection()
    _, still = traffic.obstacles(redis, a.pk, time.time())
    through = [(-4.0, -2.0), (4.0, -2.0)]
    traffic_state.request_way(redis, a, traffic_fleet.reach(a), {b.pk: None}, through)
    assert traffic_state.way_request(b)["for"] == a.pk
    traffic_state.made_way(b)
    assert traffic._idle_in_the_way(redis, a, through, still) == {}  # a replans: b stands there again
    redis.hdel(traffic_state.key("makeway"), str(b.pk))  # the request has lapsed (MAKE_WAY_TTL_S)
    assert set(traffic._idle_in_the_way(redis, a, through, still)) == {b.pk}


class StandingSession:
    """What back_off uses of a Session: a robot at a fixed pose that records the velocities it is sent."""

    def __init__(self, robot, pose):
        self.robot, self._pose, self.sent = robot, pose, []
        self.link = types.SimpleNamespace(clock=motion.ClockRate(), halt=self.halt)

    async def halt(self):
        pass

    async def pose(self):
        await asyncio.sleep(0)
        return self._pose

    async def send(self, linear, angular):
        self.sent.append((linear, angular))

    def check(self):
        pass


def test_a_robot_that_made_way_waits_while_the_other_has_no_plan_and_not_once_its_plan_has_passed(
    robots, monkeypatch
):
    a, b = robots["a"], robots["b"]
    monkeypatch.setattr(tune, "MAKE_WAY_WAIT_S", 1.0)
    monkeypatch.setattr(tune, "MAKE_WAY_POLL_S", 0.05)
    # a is busy with its instruction
    monkeypatch.setattr(traffic_fleet, "is_busy", lambda robot_id: robot_id == a.pk)
    request = {"for": a.pk, "r": traffic_fleet.reach(a), "route": [[-4.0, -2.0], [4.0, -2.0]]}
    aside, home = StandingSession(b, (0.0, -1.0, 0.0)), (0.0, -2.0)
    assert (
        asyncio.run(make_way.until_passed(aside, request, home)) >= 1.0
    )  # a waits to plan again: not passed, b stays
    redis = coordination.connection()
    traffic_state.write(redis, "waits", a.pk, {"for": b.pk, "expires": 1e12})
    # a waits for b where b stands aside: b goes back
    assert asyncio.run(make_way.until_passed(aside, request, home)) < 0.5
    redis.hdel(traffic_state.key("waits"), str(a.pk))
    store_poses([{"id": b.pk, "x": 0.0, "y": -1.0, "yaw": 0.0}])
    plan(a, (-2.0, -2.0), (2.0, -2.0), 0.3)  # a's plan passes b's home, where b stood
    entry = traffic_state.read(redis, "plans")[a.pk]
    late = [[c, r, t0 - 1000.0, t1 - 1000.0] for c, r, t0, t1 in entry["cells"]]
    # a is held up: its plan's times are past
    traffic_state.write(redis, "plans", a.pk, {**entry, "cells": late})
    assert traffic.claim(a, (-2.0, -2.0), (-1.8, -2.0)) is None  # and it is still west of b's home
    assert asyncio.run(make_way.until_passed(aside, request, home)) >= 1.0
    traffic_state.release(a, None)
    assert traffic.claim(a, (1.6, -2.0), (2.0, -2.0)) is None  # east of it, on the same plan: passed
    traffic_state.write(redis, "plans", a.pk, {**entry, "cells": late})
    assert asyncio.run(make_way.until_passed(aside, request, home)) < 0.5


def test_a_stalled_robot_backs_off_only_into_room_it_has_claimed(robots):
    from execution.handlers import back_off

    a, b = robots["a"], robots["b"]
    limits = motion.Limits(linear=0.5, angular=1.0)
    store_poses([{"id": b.pk, "x": -2.45, "y": 0.0, "yaw": 0.0}])
    blocked = StandingSession(a, (-2.0, 0.0, 0.0))  # heading east, b right behind it
    asyncio.run(back_off(blocked, limits))
    assert blocked.sent == []
    free = StandingSession(a, (-2.0, 0.0, math.pi))  # heading west, b ahead of it: nobody behind
    asyncio.run(back_off(free, limits))
    assert free.sent and all(linear < 0 for linear, _ in free.sent)


def test_a_robot_does_not_plan_again_for_its_goal_where_another_has_yet_to_pass(robots):
    """a, stopped by its goal (taken), would plan again for it from where it stands; b's plan, under way, has
    yet to pass 0.6 m from there: a stays (b goes round it, as round any robot parked) rather than plan
    anew from a spot b's earlier plan has it pass first. Once b's claim begins past it, a may plan again."""
    a, b = robots["a"], robots["b"]
    spot = (0.0, 0.6)
    path = plan(b, (0.0, -2.0), (0.0, 2.0), 0.5)
    assert traffic.claim(b, (0.0, -2.0), (0.0, -2.0), planned=(path[0][2], path[0][2])) is None
    assert traffic.yet_to_pass(a, spot)
    assert not traffic.yet_to_pass(a, (3.0, 0.6))  # nowhere near its way
    end = path[-1]
    assert traffic.claim(b, end[:2], end[:2], planned=(end[2], end[2])) is None  # b at its goal: passed
    assert not traffic.yet_to_pass(a, spot)


def test_a_parked_robot_a_trip_went_round_and_still_finds_in_its_way_is_asked_to_make_way(
    robots, monkeypatch
):
    """Robots parked shoulder to shoulder: the plan round one of them that the claims refuse would be made the
    same again (robot2 "goes round robot3" four times, then "no way through"). The first time, the waiting
    robot goes round it; once its trip has gone round it, it asks it to make way and waits for it."""
    a, b = robots["a"], robots["b"]
    redis = coordination.connection()
    traffic_state.release(b, (0.0, -2.0, 0.0))  # b parked across a's stretch, idle
    for name, value in {
        "REROUTE_AFTER_S": 0.0,
        "NOTE_WAIT_S": 0.0,
        "WAIT_POLL_S": 0.01,
        "WAIT_LIMIT_S": 0.3,
    }.items():
        monkeypatch.setattr(tune, name, value)
    sent = []

    def ask(robot):  # what traffic.ask_to_make_way does, without submitting a make_way instruction
        for pk, entry in traffic_state.read(redis, "makeway").items():
            sent.append((robot.pk, pk))
            traffic_state.write(redis, "makeway", pk, {**entry, "sent": True, "refused": ""})

    monkeypatch.setattr(traffic, "ask_to_make_way", ask)
    session, stretch, ahead = (
        StandingSession(a, (-2.0, -2.0, 0.0)),
        ((-2.0, -2.0), (2.0, -2.0)),
        [(2.0, -2.0)],
    )
    with pytest.raises(traffic.Reroute) as caught:  # first: round it
        asyncio.run(traffic.wait_for(session, *stretch, None, ahead))
    assert caught.value.around == {b.pk} and not caught.value.gave_way and sent == []
    with pytest.raises(StepFailed, match="to make way"):  # gone round it already: asked, waited for
        asyncio.run(traffic.wait_for(session, *stretch, None, ahead, gone_round=frozenset({b.pk})))
    assert sent == [(a.pk, b.pk)]
    request = traffic_state.read(redis, "makeway")[b.pk]
    assert request["for"] == a.pk and request["route"] == [[-2.0, -2.0], [2.0, -2.0]]


def test_robots_waiting_for_the_turn_to_plan_get_it_longest_trip_first(exec_settings):
    """Four robots ask while another plans: once it is done they plan one at a time, a robot making way first
    (others wait for it), then the longest expected trip first (the robots that decide when the fleet is done
    get their ways first)."""
    got = []

    async def wait_and_plan(name: str, longest: float) -> None:
        async with traffic_state.planning_turn(types.SimpleNamespace(name=name), None, longest):
            got.append(name)
            await asyncio.sleep(0.05)

    async def scene() -> None:
        async with traffic_state.planning_turn(types.SimpleNamespace(name="first"), None, 1.0):
            waiting = [
                asyncio.ensure_future(wait_and_plan(name, longest))
                for name, longest in (
                    ("short", 10.0),
                    ("long", 50.0),
                    ("aside", tune.FIRST_IN_TURN_S),
                    ("middle", 30.0),
                )
            ]
            await asyncio.sleep(0.3)  # every one of them queued meanwhile
            assert got == []  # one plan at a time
        await asyncio.wait_for(asyncio.gather(*waiting), 10)

    asyncio.run(scene())
    assert got == ["aside", "long", "middle", "short"]


def test_a_waiter_that_died_in_the_turn_queue_holds_nobody_up(exec_settings):
    """A robot queued for the turn whose executor died (it stopped renewing its liveness key) is dropped from
    the head of the queue, and the next robot gets the turn at once."""
    redis = coordination.connection()
    redis.zadd(traffic_state.key("turn:queue"), {"dead-token": -1e9})  # at the head, never alive again

    async def plan_once() -> float:
        t0 = time.monotonic()
        async with traffic_state.planning_turn(types.SimpleNamespace(name="live"), None, 5.0):
            return time.monotonic() - t0

    assert asyncio.run(plan_once()) < 1.0
    assert redis.zcard(traffic_state.key("turn:queue")) == 0
