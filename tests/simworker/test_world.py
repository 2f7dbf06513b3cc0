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


def test_shards_of_extra_robots_together_are_the_unsplit_world():
    """Two simulator shards (--extra 30 --extra-skip 0, then 30) serve what one world of 60 would: no robot's
    name or cell twice (issue 19's cluster)."""
    whole = [(r.name, r.x, r.y) for r in load_world("paper").add_extra_robots(60)]
    first = [(r.name, r.x, r.y) for r in load_world("paper").add_extra_robots(30, skip=0)]
    second = [(r.name, r.x, r.y) for r in load_world("paper").add_extra_robots(30, skip=30)]
    assert first + second == whole
    assert second[0][0] == "robot35"
    with pytest.raises(WorldFormatError, match="fits at most"):
        load_world("paper").add_extra_robots(30, skip=10_000)


def test_a_tighter_grid_packs_a_thousand_robots_apart_on_free_cells():
    fresh = load_world("paper")
    extra = fresh.add_extra_robots(1000, spacing=0.3)
    assert len({r.name for r in extra}) == 1000 and all(fresh.map.is_free(r.x, r.y) for r in extra)
    points = [(r.x, r.y) for r in extra]
    assert min(math.dist(a, b) for i, a in enumerate(points) for b in points[i + 1 :]) >= 0.29


def test_bad_world_files_are_refused(tmp_path):
    (tmp_path / "world.yaml").write_text("name: x\n")
    with pytest.raises(WorldFormatError, match="map"):
        load_world(tmp_path)
    with pytest.raises(WorldFormatError, match="cannot read"):
        load_world(tmp_path / "missing.yaml")


def test_tb3_nav2_has_a_dock_on_a_free_cell_behind_its_start(world):
    tb3 = next(r for r in world.robots if r.name == "tb3_nav2")
    assert tb3.dock == pytest.approx((-1.0, -5.1, -1.5708)) and tb3.home == tb3.dock
    assert math.dist((tb3.x, tb3.y), tb3.dock[:2]) == pytest.approx(0.6)
    assert world.map.is_free(*tb3.dock[:2])
    husky = next(r for r in world.robots if r.name == "husky")
    assert husky.dock is None and husky.home == (husky.x, husky.y, husky.yaw)  # no station: home is its start


def test_extra_robots_keep_clear_of_docks(world):
    fresh = load_world("paper")
    dock = next(r for r in fresh.robots if r.name == "tb3_nav2").dock
    assert min(math.dist((r.x, r.y), dock[:2]) for r in fresh.add_extra_robots(50)) > 1.0


def _world_with_robot(tmp_path, robot: str):
    """A world file on the paper map holding one nav2 robot written as the given YAML flow mapping."""
    from fleetcore.world import WORLDS_DIR

    (tmp_path / "world.yaml").write_text(
        f"map: {WORLDS_DIR / 'paper' / 'map.yaml'}\n"
        "endpoints: [{key: ep, port_offset: 0, ros_version: 2}]\n"
        f"robots:\n  - {robot}\n"
    )
    return tmp_path


def test_a_dock_key_left_out_takes_the_start_value(tmp_path):
    robot = "{name: r, model: turtlebot3_burger, endpoint: ep, x: 1.0, y: -1.0, yaw: 0.5, stack: nav2, dock: {y: -1.5}}"
    (spec,) = load_world(_world_with_robot(tmp_path, robot)).robots
    assert spec.dock == (1.0, -1.5, 0.5)


@pytest.mark.parametrize(
    ("dock", "stack", "error"),
    [
        ("[1, 2]", "nav2", "dock must be a mapping"),
        ("{x: 1, y: -1, z: 0}", "nav2", "unknown keys \\['z'\\]"),
        ("{x: one, y: -1}", "nav2", "must be numbers"),
        ("{x: 6.2, y: 0.0}", "nav2", "dock on a cell that is not free"),
        ("{x: 1.0, y: -1.5}", "move_base", "needs a ROS 2 robot with stack nav2"),
    ],
)
def test_bad_docks_are_refused_naming_the_robot(tmp_path, dock, stack, error):
    robot = (
        f"{{name: r, model: turtlebot3_burger, endpoint: ep, x: 1.0, y: -1.0, stack: {stack}, dock: {dock}}}"
    )
    with pytest.raises(WorldFormatError, match=f"robot 'r'.*{error}"):
        load_world(_world_with_robot(tmp_path, robot))
