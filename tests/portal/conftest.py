"""Fixtures for the portal's tests: a small fleet on a small map."""

import pytest

from fleet.models import Location, Map, TimeSlot
from robots.models import Binding, Robot


@pytest.fixture
def small_map(db):
    """A 20 x 20 cell map (1 m x 1 m at 5 cm) with a wall row and two locations."""
    cells = bytearray(400)
    cells[200:220] = bytes([100]) * 20
    grid = Map.objects.create(name="tiny", resolution=0.05, width=20, height=20, data=bytes(cells))
    Location.objects.create(map=grid, name="A", x=0.2, y=0.2)
    Location.objects.create(map=grid, name="B", x=0.8, y=0.8, kind=Location.Kind.ROOM)
    return grid


@pytest.fixture
def fleet(db, small_map):
    """Two robots: a turtlebot with bindings (one needing a person) and a husky, plus a time slot."""
    turtlebot = Robot.objects.create(
        name="turtlebot", model="turtlebot3_burger", endpoint="ws://127.0.0.1:9091",
        link_status=Robot.Link.ONLINE, state=Robot.State.READY, start_pose=[0.5, 0.5, 0.0],
        footprint=[[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]], description={"wheels": 2},
    )  # fmt: skip
    husky = Robot.objects.create(name="husky", model="husky", endpoint="ws://127.0.0.1:9092", max_linear=1.0)
    turtlebot.topics.create(name="/cmd_vel", type="geometry_msgs/Twist")
    turtlebot.topics.create(name="/odom", type="nav_msgs/Odometry")
    turtlebot.topics.create(name="/odom_raw", type="nav_msgs/Odometry")
    Binding.objects.create(
        robot=turtlebot, action="move", target="/cmd_vel", message_type="geometry_msgs/Twist", how="exact",
        confidence=1.0,
    )  # fmt: skip
    Binding.objects.create(
        robot=turtlebot, action="odometry", needs_user=True,
        candidates=[
            {"target": "/odom", "type": "nav_msgs/Odometry", "score": 0.5, "how": "pattern"},
            {"target": "/odom_raw", "type": "nav_msgs/Odometry", "score": 0.5, "how": "pattern"},
        ],
    )  # fmt: skip
    TimeSlot.objects.create(
        robot=turtlebot, start="08:00", end="10:00", goal=small_map.locations.get(name="A"), task="rotate(5)"
    )
    return {"turtlebot": turtlebot, "husky": husky}
