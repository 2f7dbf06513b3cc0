"""The demo fleet: "move all robots to ..." sends every free robot there, without collisions."""

import itertools
import math
import threading

import pytest

from execution.instructions import submit
from execution.models import Execution, TimeSlot
from places.models import Location
from robots.models import Robot
from tests.execution.helpers import parse, step, wait_final

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]


def watch_distances(sim, names, stop: threading.Event, closest: dict):
    """Record the closest approach of every pair of robots (ground truth) until stopped."""
    while not stop.is_set():
        poses = {name: sim.pose(name) for name in names}
        for a, b in itertools.combinations(names, 2):
            d = math.dist(poses[a][:2], poses[b][:2])
            closest[(a, b)] = min(d, closest.get((a, b), math.inf))
        stop.wait(0.05)


def inscribed(sim, name):
    return sim.fleet.robots[name].profile.inscribed_radius


def test_move_all_robots_sends_every_free_robot_there_without_collisions(demo_world, fleet_admin):
    sim = demo_world
    Location.objects.create(map=Location.objects.first().map, name="M", x=-1.5, y=-1.0)
    names = sorted(sim.robots)
    stop, closest = threading.Event(), {}
    watcher = threading.Thread(target=watch_distances, args=(sim, names, stop, closest), daemon=True)
    watcher.start()
    try:
        instruction = submit("move all robots to M", fleet_admin, parse=parse(step("all", -1.5, -1.0, "M")))
        instruction = wait_final(instruction, timeout=100)
    finally:
        stop.set()
        watcher.join()
    assert instruction.status == "succeeded", instruction.outcome
    executions = Execution.objects.filter(instruction=instruction).select_related("robot")
    assert sorted(e.robot.name for e in executions) == names
    for execution in executions:
        goal = execution.steps[0]["destination"]
        x, y, _ = sim.pose(execution.robot.name)
        assert math.dist((x, y), (goal["x"], goal["y"])) < 0.2, execution.robot.name  # nav stacks: 0.15
        assert goal["around"] == "M"
    assert set(Robot.objects.values_list("state", flat=True)) == {"ready"}
    for (a, b), distance in closest.items():
        assert distance > inscribed(sim, a) + inscribed(sim, b), (a, b, distance)


def test_all_robots_means_those_free_now(demo_world, fleet_admin):
    """A robot inside one of its scheduled slots is left out of "all robots"."""
    import datetime

    from django.utils import timezone

    now = timezone.localtime()
    start = (now - datetime.timedelta(minutes=1)).time()
    end = (now + datetime.timedelta(minutes=30)).time()
    if start >= end:
        pytest.skip("too close to midnight for a slot around now")
    husky = Robot.objects.get(name="husky")
    TimeSlot.objects.create(
        robot=husky, start=start, end=end, goal=Location.objects.get(name="A"), task="rotate(1)"
    )
    instruction = submit(
        "rotate all robots", fleet_admin, parse=parse(step("all", task="rotate(0.25)", action="rotate"))
    )
    names = set(Execution.objects.filter(instruction=instruction).values_list("robot__name", flat=True))
    assert "husky" not in names
    assert names == set(Robot.objects.exclude(name="husky").values_list("name", flat=True))
    assert wait_final(instruction).status == "succeeded"
