"""`dock`: a robot with a docking action server (the simulated tb3_nav2's Create 3-style /dock) drives onto its
dock; a robot without one goes back to its start pose. Judged by where the simulated robots end."""

import math

import pytest

from execution.instructions import submit
from fleetcore.world import load_world
from robots.models import Binding
from tests.execution.conftest import register
from tests.execution.helpers import wait_final

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow, pytest.mark.usefixtures("seeded_ontology")]


@pytest.fixture
def nav2_world(executor):
    from simworker.testing import running_world

    with running_world("paper", endpoints=["tb3_nav2", "turtlebot"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["tb3_nav2", "turtlebot"])
        yield sim


def test_dock_drives_a_robot_onto_its_docking_station(nav2_world, fleet_admin):
    assert Binding.objects.get(robot__name="tb3_nav2", action="dock").target.endswith("dock")
    instruction = wait_final(submit("dock tb3_nav2", fleet_admin), timeout=100)
    assert instruction.status == "succeeded", instruction.outcome
    assert "docked" in instruction.outcome
    dock = next(spec for spec in load_world("paper").robots if spec.name == "tb3_nav2").dock
    x, y, _ = nav2_world.call(nav2_world.fleet.robots["tb3_nav2"].pose)
    assert math.dist((x, y), dock[:2]) < 0.15


def test_dock_without_a_docking_action_goes_home(nav2_world, fleet_admin):
    robot = nav2_world.fleet.robots["turtlebot"]
    start = robot.pose()
    moved = wait_final(submit("move turtlebot to I", fleet_admin), timeout=100)  # 1.8 m from its start
    assert moved.status == "succeeded", moved.outcome
    assert math.dist(nav2_world.call(robot.pose)[:2], start[:2]) > 0.5
    instruction = wait_final(submit("turtlebot, go home", fleet_admin), timeout=100)
    assert instruction.status == "succeeded", instruction.outcome
    assert math.dist(nav2_world.call(robot.pose)[:2], start[:2]) < 0.2
