"""Fixtures for execution tests: a simulated world, its robots registered in the test database, fast settings."""

import os

import pytest

from simworker.testing import running_world


def pytest_configure(config):
    """Give a SQLite test database a file, so a Celery worker subprocess can share it (PostgreSQL already can)."""
    from django.conf import settings

    db = settings.DATABASES["default"]
    if db["ENGINE"].endswith("sqlite3") and not db.get("TEST", {}).get("NAME"):
        db.setdefault("TEST", {})["NAME"] = f"/tmp/fleet-test-{os.getpid()}.sqlite3"
        # Many runner threads write at once: take the write lock at BEGIN, not on the first write.
        db.setdefault("OPTIONS", {}).setdefault("transaction_mode", "IMMEDIATE")


def register(sim, keys, world="paper"):
    """Register the world's endpoints in the test database; start poses from the world where none was found."""
    from fleetcore.world import load_world
    from places.worlds import load_world_into_db
    from robots.models import Robot
    from robots.registration import register_endpoints

    results = register_endpoints([sim.urls[key] for key in keys])
    assert all(result.ok for result in results), [getattr(r, "error", r) for r in results]
    load_world_into_db(world)
    specs = {spec.name: spec for spec in load_world(world).robots}
    for robot in Robot.objects.all():
        spec = specs.get(robot.name)
        if spec and not robot.description.get("start_pose_source", "").startswith("/"):
            # The simulator publishes no initial_pose param for robots without amcl: take the world's.
            robot.start_pose = [spec.x, spec.y, spec.yaw]
            robot.save(update_fields=["start_pose"])
    return {robot.name: robot for robot in Robot.objects.all()}


@pytest.fixture
def turtle_sim(exec_settings, transactional_db):
    """The paper world with the turtlebot endpoint registered, at twice real time; no executor runs here."""
    with running_world("paper", endpoints=["turtlebot"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["turtlebot"])
        yield sim


@pytest.fixture
def turtle_world(executor, turtle_sim):
    """turtle_sim with the executor running in this process."""
    return turtle_sim


@pytest.fixture
def warehouse_pair(executor):
    """The warehouse with its Huskies and TurtleBots registered (28 robots), at twice real time."""
    with running_world("warehouse", endpoints=["husky", "tb3"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["husky", "tb3"], world="warehouse")
        yield sim


@pytest.fixture
def demo_world(executor):
    """The paper world's demo fleet: robot1..4, turtlebot, husky and tiago, registered; twice real time."""
    with running_world("paper", endpoints=["robots", "turtlebot", "husky", "tiago"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["robots", "turtlebot", "husky", "tiago"])
        yield sim


@pytest.fixture
def table12_world(executor):
    """Turtlebot, husky and tiago registered, with the paper's Table 12 time slots enabled."""
    from execution.models import TimeSlot

    with running_world("paper", endpoints=["turtlebot", "husky", "tiago"]) as sim:
        sim.robots = register(sim, ["turtlebot", "husky", "tiago"])
        TimeSlot.objects.update(enabled=True)
        yield sim


@pytest.fixture
def pose_stream(demo_world):
    """What the links process does for poses: every robot's odometry into the one store of last poses."""
    import asyncio
    import threading

    from asgiref.sync import sync_to_async

    from robots.models import Robot
    from robots.poses import PoseHub, follow, store_poses

    robots = list(Robot.objects.prefetch_related("bindings"))
    hub = PoseHub(publish=sync_to_async(store_poses))
    started = threading.Event()
    state = {}

    async def main():
        state["loop"], state["stop"] = asyncio.get_running_loop(), asyncio.Event()
        started.set()
        await follow(robots, hub, state["stop"])

    thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)  # asyncio.run ends every task
    thread.start()
    started.wait(5)
    yield hub
    state["loop"].call_soon_threadsafe(state["stop"].set)
    thread.join(10)
