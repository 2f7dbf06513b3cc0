"""A simulated robot publishing NaN odometry: refused at the gate, flagged, an alert names it, questions about it
are answered in words, a move on it fails at once with the reason and moves nothing, and the other robots' poses
keep coming. Good odometry again resolves the alert."""

import math

import pytest

from alerts.models import Alert
from execution.instructions import submit
from places.models import Location
from robots.models import Robot
from robots.poses import last_poses, pose_faults
from simworker.testing import bad_odometry
from tests.execution.helpers import parse, step, wait_final, wait_for

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]


def _fresh_pose_after(robot: Robot, t: float):
    pose = last_poses([robot.pk]).get(robot.pk)
    return pose is not None and pose["t"] > t and "fault" not in pose


def test_a_robot_publishing_nan_odometry_is_flagged_answered_in_words_and_not_moved(
    demo_world, pose_stream, fleet_admin
):
    sim = demo_world
    robot, other = Robot.objects.get(name="robot2"), Robot.objects.get(name="robot1")
    wait_for(lambda: _fresh_pose_after(robot, 0) and _fresh_pose_after(other, 0), what="both robots' poses")
    start = sim.pose("robot2")

    sim.call(bad_odometry, sim.fleet, "robot2", "nan")
    alert = wait_for(
        lambda: Alert.objects.open().filter(kind="odometry_invalid", robot=robot).first(), what="the alert"
    )
    assert alert.message.startswith("robot2's odometry is invalid (x is NaN) since ")
    flagged = pose_faults([robot.pk])[robot.pk]
    assert flagged["fault"] == "x is NaN" and math.isfinite(flagged["x"])  # the last good pose, flagged
    seen = last_poses([other.pk])[other.pk]["t"]
    wait_for(lambda: _fresh_pose_after(other, seen), what="robot1's poses still coming")

    place = Location.objects.get(name="A")
    ask = step(["robot2"], place.x, place.y, "A", action="report_distance")
    question = wait_final(submit("how far is robot2 from A", fleet_admin, parse=parse(ask)))
    assert "robot2's odometry is invalid (x is NaN) since " in question.outcome
    assert "I cannot say how far it is from A" in question.outcome

    goal = (start[0] + 1.0, start[1])
    move = wait_final(submit("move robot2 to X", fleet_admin, parse=parse(step(["robot2"], *goal, "X"))))
    assert move.status == "failed" and "robot2's odometry is invalid (x is NaN)" in move.outcome, move.outcome
    assert math.dist(sim.pose("robot2")[:2], start[:2]) < 0.02  # nothing drove it on a pose it does not have

    sim.call(bad_odometry, sim.fleet, "robot2", None)
    wait_for(lambda: _fresh_pose_after(robot, seen), what="robot2's good poses again")
    wait_for(lambda: Alert.objects.get(pk=alert.pk).resolved_at is not None, what="the alert resolved")
