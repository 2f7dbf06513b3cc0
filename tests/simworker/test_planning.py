"""fleetcore.planning: A* on the occupancy grid, and around robots the map does not show."""

import math

from fleetcore.planning import Planner
from fleetcore.world import load_world

B, C, SPOT_I = (-2.0, 2.0), (2.0, -2.0), (-1.0, 1.0)  # the straight line from B to C passes through I


def clearance(path, start, point) -> float:
    """The closest the path's legs come to a point."""
    legs = zip([start, *path], path, strict=False)
    return min(
        math.dist(point, (a[0] + (b[0] - a[0]) * t / 50, a[1] + (b[1] - a[1]) * t / 50))
        for a, b in legs
        for t in range(51)
    )


def test_plan_is_straight_on_a_free_map_and_bends_around_a_robot_it_is_told_of():
    planner = Planner(load_world("paper").map, 0.105)
    assert planner.plan(B, C) == [C]  # nothing on the map between B and C
    around = planner.plan(B, C, avoid=[(*SPOT_I, 0.3)])  # TIAGo parked at I
    assert around[-1] == C and len(around) >= 2
    assert clearance(around, B, SPOT_I) > 0.3 + 0.105


def test_a_goal_inside_another_robot_is_unreachable():
    planner = Planner(load_world("paper").map, 0.105)
    assert planner.plan(B, SPOT_I, avoid=[(*SPOT_I, 0.3)]) is None


def test_a_robot_pressed_against_another_can_back_out_and_go_around():
    planner = Planner(load_world("paper").map, 0.105)
    pressed = (-1.3, 1.3)  # touching the robot parked at I
    around = planner.plan(pressed, C, avoid=[(*SPOT_I, 0.3)])
    assert around is not None and around[-1] == C
    assert clearance(around[1:], around[0], SPOT_I) > 0.3 + 0.105
