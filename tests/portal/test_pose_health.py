"""A robot's pose health in the API and the answers: its age, "stale (3.2 s)", odometry refused at the gate, and
a last_seen that is the freshest sign of life, not a heartbeat that stopped."""

import time
from datetime import timedelta

import pytest
from django.utils import timezone

from execution import queries
from fleetcore.interpretation import Interpretation
from robots.models import Robot
from robots.poses import forget_poses, store_poses


def pose(robot, age: float, **extra) -> dict:
    return {
        "id": robot.pk,
        "x": 0.2,
        "y": 0.5,
        "yaw": 0.0,
        "v": 0.0,
        "w": 0.0,
        "t": time.time() - age,
        **extra,
    }


def api_robot(client, name: str) -> dict:
    return next(row for row in client.get("/api/robots").json() if row["name"] == name)


def test_the_api_says_each_robots_pose_age_and_a_stale_one_is_stale(fleet, client_for, viewer):
    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    store_poses([pose(turtlebot, 0.1), pose(husky, 3.2)])
    client = client_for(viewer)
    fresh, stale = api_robot(client, "turtlebot"), api_robot(client, "husky")
    assert (fresh["stale"], fresh["pose_status"]) == (False, "live")
    assert stale["stale"] is True and stale["pose_age"] >= 3.2
    assert stale["pose_status"].startswith("stale (3.")
    assert client.get("/api/robots/husky").json()["pose_status"].startswith("stale (3.")


def test_last_seen_is_the_freshest_sign_of_life(fleet, client_for, viewer):
    """The links process's heartbeat was 5 minutes old while its poses came: the API said 5 minutes."""
    turtlebot = fleet["turtlebot"]
    Robot.objects.filter(pk=turtlebot.pk).update(last_seen=timezone.now() - timedelta(minutes=5))
    store_poses([pose(turtlebot, 0.5)])
    seen = api_robot(client_for(viewer), "turtlebot")["last_seen"]
    age = (timezone.now() - timezone.datetime.fromisoformat(seen)).total_seconds()
    assert 0.4 <= age < 5


def test_a_robot_whose_odometry_is_refused_says_so_in_the_api_and_in_words(fleet, client_for, viewer):
    husky = fleet["husky"]
    store_poses([pose(husky, 4.0, fault="x is NaN", fault_since=time.time() - 4.0)])
    row = api_robot(client_for(viewer), "husky")
    assert (row["stale"], row["pose_fault"], row["pose_status"]) == (
        True,
        "x is NaN",
        "odometry invalid: x is NaN",
    )

    step = {
        "action": "report_distance",
        "robots": ["husky"],
        "destination": {"name": "A", "x": 0.2, "y": 0.2},
    }
    words, _ = queries.answer(Interpretation.direct([step], ""))
    assert words.startswith("husky's odometry is invalid (x is NaN) since ")
    assert words.endswith("; I cannot say how far it is from A.")
    where, _ = queries.answer(Interpretation.direct([{"action": "report_position", "robots": ["husky"]}], ""))
    assert "odometry is invalid (x is NaN)" in where and "last good position was (0.20, 0.50)" in where


def test_a_stale_pose_is_said_stale_in_the_answers(fleet):
    store_poses([pose(fleet["turtlebot"], 3.5)])
    where, _ = queries.answer(
        Interpretation.direct([{"action": "report_position", "robots": ["turtlebot"]}], "")
    )
    assert where.startswith("turtlebot was, 3.") and "s ago (stale), at (0.20, 0.50)" in where


@pytest.fixture(autouse=True)
def _no_poses_left(fleet):
    """Poses live in the cache (Redis), not the test's database: none from one test may reach the next."""

    yield
    forget_poses([robot.pk for robot in fleet.values()])


def test_a_robot_not_heard_of_for_a_minute_has_no_pose_though_others_keep_theirs(fleet, client_for, viewer):
    """Every pose is a field of one hash, which expires as a whole: a robot whose odometry stopped a minute ago
    (its link gone) while others' still come is not heard of, as when each pose expired on its own."""
    from robots.poses import POSE_TTL_S, last_poses

    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    store_poses([pose(turtlebot, 0.1), pose(husky, POSE_TTL_S + 1)])
    assert set(last_poses([turtlebot.pk, husky.pk])) == {turtlebot.pk}
    client = client_for(viewer)
    assert api_robot(client, "husky")["pose_status"] == "no pose"
    assert api_robot(client, "turtlebot")["pose_status"] == "live"
