"""WorldProcess: the paper world in a spawned child process, driven over its pipe."""

import math

import pytest

from fleetcore.world import load_world
from simworker.testing import WorldProcess

pytestmark = pytest.mark.timeout(120)
ROBOT = "turtlebot"
HOME_TOLERANCE_M = 0.01


def test_world_process_serves_endpoints_poses_contacts_and_home(bridge):
    spec = next(robot for robot in load_world("paper").robots if robot.name == ROBOT)
    with WorldProcess("paper") as sim:
        assert all(url.startswith("ws://127.0.0.1:") for url in sim.urls.values())
        reply = bridge(sim.urls[spec.endpoint]).call("/rosapi/get_time")  # the child's server answers
        assert reply["result"] is True
        assert math.dist(sim.pose(ROBOT)[:2], (spec.x, spec.y)) < HOME_TOLERANCE_M
        sim.home([ROBOT])
        x, y, yaw = sim.pose(ROBOT)
        assert math.dist((x, y), (spec.x, spec.y)) < HOME_TOLERANCE_M and abs(yaw - spec.yaw) < 0.01
        assert sim.contacts() == 0 and sim.touched() == []
        with pytest.raises(RuntimeError, match="KeyError"):  # the caller's mistake, reported, world still up
            sim.pose("nobody")
        assert sim.pose(ROBOT) == (x, y, yaw)
    assert sim.process.exitcode == 0  # SIGTERM stopped its loop: servers closed, no kill needed
