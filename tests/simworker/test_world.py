"""The paper world: map, locations, robots, endpoints, schedules; every location reachable by every robot."""

import math

import pytest

from fleetcore.catalog import model
from fleetcore.planning import Planner
from fleetcore.world import WorldFormatError, load_world
from fleetcore.worlds.make_paper_map import build


@pytest.fixture(scope="module")
def world():
    """The shipped paper world."""
    return load_world("paper")


def test_paper_world_has_the_papers_locations_and_rooms(world):
    places = {loc.name: (loc.x, loc.y) for loc in world.locations}
    assert places["A"] == (2, 2) and places["E"] == (5, -5) and places["I"] == (-1, 1)
    assert {n for n, *_ in [(loc.name, loc.kind) for loc in world.locations if loc.kind == "room"]} == {
        "Room 1",
        "Room 2",
        "Room 3",
        "Room 4",
    }
    width, height = world.map.size_m
    assert 12 <= width <= 14 and 12 <= height <= 14


def test_committed_map_matches_the_generator(world):
    assert build().data == world.map.data


def test_schedules_follow_table_12(world):
    slots = {(s.robot, s.start): (s.goal, s.task) for s in world.schedules}
    assert slots[("turtlebot", "08:00")] == ("A", "rotate(5)")
    assert slots[("husky", "10:00")] == ("E", "rotate(10)")
    assert slots[("tiago", "14:00")] == ("I", "rotate(15)")
    assert ("turtlebot", "10:00") not in slots  # FreeTime
    assert len(world.schedules) == 9


def test_first_four_endpoints_hold_exactly_seven_robots(world):
    first_four = {e.key for e in world.endpoints if e.port_offset < 4}
    assert len([r for r in world.robots if r.endpoint in first_four]) == 7


@pytest.mark.parametrize("robot", ["turtlebot", "husky", "tiago", "spot", "tb3_nav2", "robot1"])
def test_every_location_is_reachable_by_every_robot(world, robot):
    spec = next(r for r in world.robots if r.name == robot)
    planner = Planner(world.map, model(spec.model).inscribed_radius)
    for loc in world.locations:
        path = planner.plan((spec.x, spec.y), (loc.x, loc.y))
        assert path is not None, f"{robot} cannot reach {loc.name}"
        assert math.dist(path[-1], (loc.x, loc.y)) < 1e-9


def test_extra_robots_are_placed_on_free_cells_apart(world):
    fresh = load_world("paper")
    extra = fresh.add_extra_robots(50)
    assert [r.name for r in extra[:2]] == ["robot5", "robot6"] and extra[0].namespace == "/robot5"
    assert all(fresh.map.is_free(r.x, r.y) for r in extra)
    points = [(r.x, r.y) for r in fresh.robots]
    assert min(math.dist(a, b) for i, a in enumerate(points) for b in points[i + 1 :]) >= 0.44


def test_bad_world_files_are_refused(tmp_path):
    (tmp_path / "world.yaml").write_text("name: x\n")
    with pytest.raises(WorldFormatError, match="map"):
        load_world(tmp_path)
    with pytest.raises(WorldFormatError, match="cannot read"):
        load_world(tmp_path / "missing.yaml")
