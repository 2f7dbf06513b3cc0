"""The warehouse world: 32+ robots of mixed models on few endpoints, every place reachable, served by the
simulator."""

import itertools
import math
from collections import Counter

import pytest

from fleetcore import catalog
from fleetcore.planning import Planner
from fleetcore.world import load_world
from fleetcore.worlds import make_warehouse_map
from simworker.testing import running_world


@pytest.fixture(scope="module")
def world():
    return load_world("warehouse")


def test_committed_files_match_the_generator(world):
    assert make_warehouse_map.build().data == world.map.data
    assert [r.name for r in world.robots] == [r["name"] for r in make_warehouse_map.robots()]


def test_32_or_more_robots_of_four_models_on_four_endpoints(world):
    models = Counter(r.model for r in world.robots)
    assert len(world.robots) >= 32
    assert set(models) == {"turtlebot3_burger", "husky", "tiago", "spot"}
    assert len(world.endpoints) == 4


def test_robots_start_apart_on_free_ground(world):
    for a, b in itertools.combinations(world.robots, 2):
        gap = math.dist((a.x, a.y), (b.x, b.y))
        reach = catalog.model(a.model).circumscribed_radius + catalog.model(b.model).circumscribed_radius
        assert gap > reach + 0.1, (a.name, b.name)


@pytest.mark.parametrize("robot", ["husky1", "spot4", "tiago1", "tb20"])
def test_every_place_is_reachable_by_every_model(world, robot):
    spec = next(r for r in world.robots if r.name == robot)
    planner = Planner(world.map, catalog.model(spec.model).inscribed_radius)
    for place in world.locations:
        assert planner.plan((spec.x, spec.y), (place.x, place.y)) is not None, (robot, place.name)


@pytest.mark.timeout(60)
def test_the_simulator_serves_every_warehouse_robot():
    with running_world("warehouse") as sim:
        assert set(sim.urls) == {"husky", "spot", "tb3", "tiago"}
        assert len(sim.fleet.robots) >= 32
        x, y, _ = sim.pose("tb20")
        assert (x, y) == pytest.approx((20.5, 1.0), abs=0.01)
