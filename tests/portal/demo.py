"""A running demo fleet for the end-to-end browser tests and the screenshots: simulated world + pose stream."""

import asyncio
import os
import threading
from contextlib import contextmanager
from pathlib import Path

import pytest

SCREENSHOTS = Path(__file__).resolve().parents[2] / "docs" / "screenshots"
SCREENSHOT_MARKS = [  # the screenshot modules: written on demand only (they overwrite docs/screenshots)
    pytest.mark.browser,
    pytest.mark.slow,
    pytest.mark.timeout(180),
    pytest.mark.skipif(
        not os.environ.get("FLEET_SCREENSHOTS"), reason="set FLEET_SCREENSHOTS=1 to write them"
    ),
]

DEMO_KEYS = ("robots", "namespaced", "turtlebot", "husky", "tiago")  # "robots": the namespaced endpoint


@contextmanager
def pose_stream():
    """Stream every registered robot's poses to the browsers (what robotlinks does in `make run`)."""
    from robots.models import Robot
    from robots.poses import PoseHub, follow

    state = {}

    def run():
        with asyncio.Runner() as runner:  # which, closing, ends what still runs on its loop (keepalives)
            state["loop"] = runner.get_loop()
            stop = asyncio.Event()
            state["stop"] = stop
            robots = list(Robot.objects.prefetch_related("bindings"))
            runner.run(follow(robots, PoseHub(), stop))

    thread = threading.Thread(target=run, name="poses", daemon=True)
    thread.start()
    try:
        yield
    finally:
        while "stop" not in state and thread.is_alive():
            thread.join(0.05)
        if "stop" in state:
            state["loop"].call_soon_threadsafe(state["stop"].set)
        thread.join(timeout=10)


@contextmanager
def demo_world():
    """The paper world running, its map and locations in the database; yields the world handle."""
    from places.worlds import load_world_into_db
    from simworker.testing import running_world

    with running_world("paper") as world:
        load_world_into_db("paper")
        yield world


def demo_urls(world) -> list[str]:
    return [world.urls[key] for key in DEMO_KEYS if key in world.urls]
