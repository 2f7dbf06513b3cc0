"""The legged robot moves on instruction: Spot's body-frame go_to_pose is no navigation stack, so the portal drives
it through its cmd_vel (judged by where the simulated Spot ends)."""

import math

import pytest

from execution.instructions import submit
from places.models import Location
from robots.models import Binding
from tests.execution.conftest import register
from tests.execution.helpers import wait_final

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow, pytest.mark.usefixtures("seeded_ontology")]


@pytest.fixture
def spot_world(executor):
    from simworker.testing import running_world

    with running_world("paper", endpoints=["spot"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["spot"])
        yield sim


def test_move_spot_moves_spot(spot_world, fleet_admin):
    assert not Binding.objects.get(
        robot__name="spot", action="navigate"
    ).target  # go_to_pose is not navigation
    Location.objects.create(map=Location.objects.first().map, name="Porch", x=3.0, y=1.5)
    start = spot_world.call(spot_world.fleet.robots["spot"].pose)
    instruction = wait_final(submit("move spot to Porch", fleet_admin), timeout=100)
    assert instruction.status == "succeeded", instruction.outcome
    x, y, _ = spot_world.call(spot_world.fleet.robots["spot"].pose)
    assert math.dist((x, y), (3.0, 1.5)) < 0.15 and math.dist((x, y), start[:2]) > 0.8
