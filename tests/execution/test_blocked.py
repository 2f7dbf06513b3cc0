"""A robot commanded to move that makes no progress is stalled: the route is planned again, not pushed into."""

import math
import time
from types import SimpleNamespace

import pytest

from execution.steps import Progress, Stalled, StepFailed, drive
from fleetcore import motion


class StuckSession:
    """Odometry that never changes, at 50 Hz; records what is sent."""

    def __init__(self):
        self.robot = SimpleNamespace(name="tb")
        self.link = SimpleNamespace(halt=lambda: self.sent.append("halt"))
        self.sent = []

    def pose(self):
        time.sleep(0.02)
        return (0.0, 0.0, 0.0)

    def send(self, v, w):
        self.sent.append((v, w))


LIMITS = motion.Limits(linear=0.22, angular=2.84)


def test_a_robot_that_does_not_move_is_stalled_and_halted():
    session = StuckSession()
    controller = motion.GoToGoal((1.0, 0.0), LIMITS)
    with pytest.raises(Stalled, match=r"tb: no progress for 0.3 s near \(0\.0, 0\.0\)"):
        drive(session, controller, limit_s=10.0, stall_s=0.3, goal=(1.0, 0.0))
    assert session.sent[-1] == "halt"
    assert any(isinstance(c, tuple) and c[0] > 0 for c in session.sent)  # it was told to drive


def test_without_blocked_detection_only_the_time_limit_ends_it():
    session = StuckSession()
    with pytest.raises(StepFailed) as failure:
        drive(session, motion.GoToGoal((1.0, 0.0), LIMITS), limit_s=0.3)
    assert not isinstance(failure.value, Stalled)
    assert "did not finish within" in str(failure.value)


def test_progress_is_getting_closer_or_turning_towards_the_goal():
    progress = Progress(limit=60.0, window=0.05, goal=(1.0, 0.0))
    assert progress.update((0.0, 0.0, 3.0)) is None  # facing away
    time.sleep(0.03)
    assert progress.update((0.0, 0.0, 2.0)) is None  # turning towards it: progress
    time.sleep(0.03)
    assert progress.update((0.1, 0.0, 0.0)) is None  # closer: progress
    time.sleep(0.03)
    assert progress.update((0.1, 0.01, 0.0)) is None  # a little sideways: not progress, but within the window
    time.sleep(0.04)
    assert progress.update((0.1, -0.01, 0.01)) == "stalled"  # wiggling in place for longer than the window


def test_a_motion_is_late_after_its_limit_even_with_progress():
    progress = Progress(limit=0.05, window=10.0, goal=(10.0, 0.0))
    assert progress.update((0.0, 0.0, 0.0)) is None
    time.sleep(0.06)
    assert progress.update((1.0, 0.0, 0.0)) == "late"


@pytest.mark.slow
@pytest.mark.timeout(150)
@pytest.mark.parametrize(
    ("robot", "how"),
    [("turtlebot", "own controller, planned route"), ("robot1", "its move_base")],
)
def test_a_robot_sent_onto_a_parked_robot_fails_blocked_by_it_and_rests(
    demo_world, pose_stream, fleet_admin, robot, how
):
    """The goal is where the Husky (50 kg) is parked: the robot drives up to it and cannot go on."""
    from alerts.models import Alert
    from execution.instructions import submit
    from execution.steps import travel_time
    from robots.models import Robot
    from tests.execution.helpers import at_rest, parse, step, wait_final, wait_for, without_command_timeout

    sim = demo_world
    without_command_timeout(sim, robot)  # at rest must be the executor's doing, not the base's timeout
    husky = sim.pose("husky")
    wait_for(lambda: _known(Robot.objects.get(name="husky")), what="poses")
    instruction = submit(f"move {robot} to X", fleet_admin, parse=parse(step([robot], *husky[:2], "X")))
    final = wait_final(instruction, timeout=130)

    assert final.status == "failed", final.outcome
    assert f"{robot}: blocked by husky at X" in final.outcome
    start = Robot.objects.get(name=robot).start_pose
    limits = motion.Limits(
        Robot.objects.get(name=robot).max_linear, Robot.objects.get(name=robot).max_angular
    )
    deadline = travel_time(
        math.dist(start[:2], husky[:2]) * 1.5, math.pi, limits, 0.5
    )  # the slowest (nav) leg
    assert (final.finished_at - final.received_at).total_seconds() < deadline  # failed by the stall, in time
    assert wait_for(lambda: at_rest(sim, robot), timeout=2, what=f"{robot} at rest")
    assert math.dist(sim.pose("husky")[:2], husky[:2]) < 0.3  # still there: a TurtleBot cannot push it away
    stuck = Alert.objects.open().get(kind="robot_stuck", robot__name=robot)
    assert "blocked by husky" in stuck.message
    failed = Alert.objects.open().filter(kind="step_failed", robot__name=robot)
    assert wait_for(failed.exists, timeout=5, what="the step_failed alert (raised after the settle)")


def _known(robot) -> bool:
    from robots.poses import last_poses

    return robot.pk in last_poses([robot.pk])
