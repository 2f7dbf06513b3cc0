"""A robot commanded to move that makes no progress is stalled: the route is planned again, not pushed into."""

import asyncio
import math
from types import SimpleNamespace

import pytest

from execution.steps import Progress, Stalled, StepFailed, at_rest, drive
from fleetcore import motion


class StuckSession:
    """Odometry that never changes, at 50 Hz; records what is sent."""

    def __init__(self):
        self.robot = SimpleNamespace(name="tb")
        self.link = SimpleNamespace(halt=self.halt)
        self.sent = []

    async def halt(self):
        self.sent.append("halt")

    async def pose(self):
        await asyncio.sleep(0.02)
        return (0.0, 0.0, 0.0)

    async def send(self, v, w):
        self.sent.append((v, w))


LIMITS = motion.Limits(linear=0.22, angular=2.84)


def test_a_robot_that_does_not_move_is_stalled_and_halted():
    session = StuckSession()
    controller = motion.GoToGoal((1.0, 0.0), LIMITS)
    with pytest.raises(Stalled, match=r"tb: no progress for 0.3 s near \(0\.0, 0\.0\)"):
        asyncio.run(drive(session, controller, limit_s=10.0, stall_s=0.3, goal=(1.0, 0.0)))
    assert session.sent[-1] == "halt"
    assert any(isinstance(c, tuple) and c[0] > 0 for c in session.sent)  # it was told to drive


def test_without_blocked_detection_only_the_time_limit_ends_it():
    session = StuckSession()
    with pytest.raises(StepFailed) as failure:
        asyncio.run(drive(session, motion.GoToGoal((1.0, 0.0), LIMITS), limit_s=0.3))
    assert not isinstance(failure.value, Stalled)
    assert "did not finish within" in str(failure.value)


def test_progress_is_getting_closer_or_turning_towards_the_goal():
    # The clock is given, not slept: a loaded machine must not stretch 30 ms past the window.
    progress = Progress(limit=60.0, window=0.05, goal=(1.0, 0.0), started=0.0, since=0.0)
    assert progress.update((0.0, 0.0, 3.0), now=0.0) is None  # facing away
    assert progress.update((0.0, 0.0, 2.0), now=0.03) is None  # turning towards it: progress
    assert progress.update((0.1, 0.0, 0.0), now=0.06) is None  # closer: progress
    assert (
        progress.update((0.1, 0.01, 0.0), now=0.09) is None
    )  # a little sideways: not progress, within the window
    assert (
        progress.update((0.1, -0.01, 0.01), now=0.13) == "stalled"
    )  # wiggling in place longer than the window


def test_a_motion_is_late_after_its_limit_even_with_progress():
    progress = Progress(limit=0.05, window=10.0, goal=(10.0, 0.0), started=0.0, since=0.0)
    assert progress.update((0.0, 0.0, 0.0), now=0.0) is None
    assert progress.update((1.0, 0.0, 0.0), now=0.06) == "late"


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_a_robot_driven_into_an_obstacle_nobody_knows_fails_stuck_in_time_and_rests(
    demo_world, pose_stream, fleet_admin
):
    """A box the map does not show stands on the goal (robots parked there are avoided: the coordination
    tests): the TurtleBot drives up to it, backs off, tries again, and the step fails with the reason."""
    from alerts.models import Alert
    from execution.instructions import submit
    from execution.steps import travel_time
    from robots.models import Robot
    from tests.execution.helpers import at_rest, parse, step, wait_final, wait_for, without_command_timeout

    sim, robot = demo_world, "turtlebot"
    without_command_timeout(sim, robot)  # at rest must be the executor's doing, not the base's timeout
    start = sim.pose(robot)
    goal = (start[0] + 1.0, start[1])
    sim.call(lambda: sim.fleet.physics.add_fixture(goal[0], goal[1], 0.0, 0.5, 0.5))
    instruction = submit(f"move {robot} to X", fleet_admin, parse=parse(step([robot], *goal, "X")))
    final = wait_final(instruction, timeout=130)

    assert final.status == "failed", final.outcome
    assert f"{robot}: stuck on the way to X" in final.outcome and "no progress" in final.outcome
    row = Robot.objects.get(name=robot)
    limits = motion.Limits(row.max_linear, row.max_angular)
    deadline = travel_time(math.dist(start[:2], goal) * 1.5, math.pi, limits.scaled(0.5))
    assert (final.finished_at - final.received_at).total_seconds() < deadline  # failed by the stall, in time
    assert wait_for(lambda: at_rest(sim, robot), timeout=2, what=f"{robot} at rest")
    assert math.dist(sim.pose(robot)[:2], goal) > 0.25  # it never got into the box
    failed = Alert.objects.open().filter(kind="step_failed", robot__name=robot)
    assert wait_for(failed.exists, timeout=5, what="the stall's alert become step_failed (after the settle)")
    alert = Alert.objects.get(
        robot__name=robot
    )  # one stall, one alert: robot_stuck, then the failure it ended in
    assert "stuck on the way to X" in alert.message and alert.count >= 2


def _known(robot) -> bool:
    from robots.poses import last_poses

    return robot.pk in last_poses([robot.pk])


class ScriptedSession(StuckSession):
    """Odometry read from a script of poses (x, y, yaw), the last one repeated."""

    def __init__(self, poses):
        super().__init__()
        self.poses = iter(poses)
        self.now = None

    async def pose(self):
        self.now = next(self.poses, self.now)
        return self.now


def test_where_a_step_ended_is_read_once_the_robot_is_at_rest_not_as_it_was_told_to_stop():
    # a robot told to stop that coasts on, slower each message, then stands
    session = ScriptedSession([(x, 0.0, 0.0) for x in (1.00, 1.04, 1.07, 1.09, 1.10, 1.10)])
    assert asyncio.run(at_rest(session)) == (1.10, 0.0, 0.0)  # not 1.00, where it was when told to stop
    assert session.sent == ["halt"]


def test_a_robot_turning_on_the_spot_is_not_at_rest_until_it_stops_turning():
    """A turn's outcome is said from where it came to rest: a robot that stands where it was but still turns
    (slowing down within its acceleration limit) is not at rest yet."""
    session = ScriptedSession([(1.0, 0.0, yaw) for yaw in (1.50, 1.58, 1.64, 1.68, 1.70, 1.70)])
    assert asyncio.run(at_rest(session)) == (1.0, 0.0, 1.70)  # not 1.50: it turned on 0.2 rad after the stop
