"""Fixtures of the interpreter's tests: the paper's demo fleet, as plain data and as database rows."""

import uuid

import pytest
from django.core.cache import cache

from interpreter import versions
from interpreter.lexicon import Fleet, Grammar, Lexicon, Place, RobotInfo
from interpreter.terms import seed_terms
from tests.conftest import seed_ontology

ROBOTS = [
    ("turtlebot", "turtlebot3_burger", "wheeled"),
    ("husky", "husky", "wheeled"),
    ("tiago", "tiago", "wheeled"),
    *[(f"robot{i}", "turtlebot3_burger", "wheeled") for i in range(1, 5)],
    ("spot", "spot", "legged"),
    ("tb3_nav2", "turtlebot3_burger", "wheeled"),
]
WAYPOINTS = {
    "A": (2, 2), "B": (-2, 2), "C": (2, -2), "D": (5, 5), "E": (5, -5),
    "F": (0, 5), "G": (1, -1), "H": (0, 1), "I": (-1, 1),
}  # fmt: skip
ROOMS = {f"Room {i}": (float(i), -float(i)) for i in range(1, 5)}


def paper_fleet() -> Fleet:
    places = [Place(n, float(x), float(y), "Waypoint") for n, (x, y) in WAYPOINTS.items()]
    places += [Place(n, x, y, "Room") for n, (x, y) in ROOMS.items()]
    return Fleet([RobotInfo(*r) for r in ROBOTS], places)


@pytest.fixture(scope="session")
def grammar() -> Grammar:
    """The seed ontology and the paper's fleet, without Django."""
    return Grammar(Lexicon(seed_terms()), paper_fleet())


@pytest.fixture
def fresh_store():
    """Forget this process's snapshot and give the version tokens new values."""
    from interpreter.service import store

    store().reset()
    store().local_changes.clear()
    cache.set(versions.ONTOLOGY_KEY, uuid.uuid4().hex, None)
    cache.set(versions.FLEET_KEY, uuid.uuid4().hex, None)
    yield store()
    store().reset()


@pytest.fixture
def paper_world(db, fresh_store):
    """The demo world "paper" as Robot and Location rows, and the seed ontology (tests.conftest.seed_ontology)."""
    from places.models import Location, Map
    from robots.models import Robot

    seed_ontology()

    for i, (name, model, drive) in enumerate(ROBOTS):
        Robot.objects.create(name=name, model=model, drive=drive, endpoint=f"ws://127.0.0.1:{9090 + i}")
    the_map = Map.objects.create(name="paper", resolution=0.05, width=10, height=10, data=bytes(100))
    for name, (x, y) in WAYPOINTS.items():
        Location.objects.create(map=the_map, name=name, x=x, y=y, kind="waypoint")
    for name, (x, y) in ROOMS.items():
        Location.objects.create(map=the_map, name=name, x=x, y=y, kind="room")
    return the_map
