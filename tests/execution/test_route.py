"""Robots without a navigation stack drive around what the map shows, not into it."""

import math

import pytest

from execution.instructions import submit
from execution.route import footprint_radius, route
from places.worlds import load_world_into_db
from robots.models import Robot
from robots.poses import forget_poses, store_poses
from tests.execution.helpers import parse, step, wait_final

CRATE = ((1.4, 2.6), (0.1, 0.5))  # the paper world's crate (fleetcore/worlds/make_paper_map.py)
START, BEHIND_CRATE = (-2.0, -0.5), (3.0, 0.8)  # the straight line between clips the crate


def crosses_crate(a, b, margin: float) -> bool:
    (x0, x1), (y0, y1) = CRATE
    for i in range(201):
        x, y = a[0] + (b[0] - a[0]) * i / 200, a[1] + (b[1] - a[1]) * i / 200
        if x0 - margin <= x <= x1 + margin and y0 - margin <= y <= y1 + margin:
            return True
    return False


def test_footprint_radius_is_half_the_narrow_side():
    assert footprint_radius([[-0.5, -0.3], [-0.5, 0.3], [0.5, 0.3], [0.5, -0.3]]) == pytest.approx(0.3)
    assert footprint_radius([]) == pytest.approx(0.15)
    assert footprint_radius("garbage") == pytest.approx(0.15)


@pytest.mark.django_db
def test_route_goes_around_the_crate_and_ends_at_the_goal():
    load_world_into_db("paper")
    robot = Robot(name="tb", footprint=[[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]])
    assert crosses_crate(START, BEHIND_CRATE, 0.1)  # the paper's Figure 7 would drive into it
    waypoints = route(robot, START, BEHIND_CRATE)
    assert len(waypoints) >= 2
    assert waypoints[-1] == BEHIND_CRATE
    legs = zip([START, *waypoints], waypoints, strict=False)
    assert not any(crosses_crate(a, b, 0.1) for a, b in legs)


@pytest.mark.django_db
def test_without_a_map_the_route_is_the_straight_line():
    assert route(Robot(name="tb"), START, BEHIND_CRATE) == [BEHIND_CRATE]


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_turtlebot_reaches_a_goal_behind_the_crate(turtle_world, fleet_admin):
    instruction = submit(
        "move turtlebot to X", fleet_admin, parse=parse(step(["turtlebot"], *BEHIND_CRATE, "X"))
    )
    assert wait_final(instruction, timeout=75).status == "succeeded"
    x, y, _ = turtle_world.pose("turtlebot")
    assert math.dist((x, y), BEHIND_CRATE) < 0.15


def _min_clearance(start, waypoints, point) -> float:
    legs = zip([start, *waypoints], waypoints, strict=False)
    samples = [
        (a[0] + (e[0] - a[0]) * t / 50, a[1] + (e[1] - a[1]) * t / 50) for a, e in legs for t in range(51)
    ]
    return min(math.dist(point, p) for p in samples)


B, C, I_ = (-2.0, 2.0), (2.0, -2.0), (-1.0, 1.0)  # I lies on the straight line from B to C
SQUARE = [[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]]
BIG_SQUARE = [[-0.3, -0.3], [-0.3, 0.3], [0.3, 0.3], [0.3, -0.3]]


@pytest.mark.django_db
def test_route_goes_around_a_robot_parked_on_the_way():

    load_world_into_db("paper")
    robot = Robot.objects.create(name="tb", endpoint="ws://x/1", footprint=SQUARE)
    parked = Robot.objects.create(name="parked", endpoint="ws://x/2", footprint=BIG_SQUARE)
    assert route(robot, B, C) == [C]
    store_poses([{"id": parked.pk, "x": I_[0], "y": I_[1], "yaw": 0.0}])
    try:
        around = route(robot, B, C)
    finally:
        forget_poses([parked.pk])
    assert around[-1] == C and len(around) >= 2
    assert _min_clearance(B, around, I_) > 0.3 + 0.1  # clear of the parked robot's body


@pytest.mark.django_db
def test_route_keeps_clear_of_where_a_robot_under_way_is_going(fleet_admin):
    """Table 12's last slot: TIAGo drives to I while robot1 goes from B to C, across I."""
    from execution.models import Execution, Instruction

    load_world_into_db("paper")
    robot = Robot.objects.create(name="tb", endpoint="ws://x/1", footprint=SQUARE)
    tiago = Robot.objects.create(name="tiago", endpoint="ws://x/2", footprint=BIG_SQUARE)
    instruction = Instruction.objects.create(text="move tiago to I", user=fleet_admin)
    going = {"action": "move", "destination": {"name": "I", "x": I_[0], "y": I_[1]}}
    execution = Execution.objects.create(instruction=instruction, robot=tiago, steps=[going])
    assert route(robot, B, C) == [C]  # queued, not yet under way: nothing to keep clear of
    execution.status = Execution.Status.RUNNING
    execution.save()
    around = route(robot, B, C)
    assert around[-1] == C and _min_clearance(B, around, I_) > 0.3 + 0.1
