"""A robot commanded to move that does not move is blocked: the route is planned again, not pushed into."""

import time
from types import SimpleNamespace

import pytest

from execution.steps import Blocked, StepFailed, drive
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


def test_a_robot_that_does_not_move_is_blocked_and_halted():
    session = StuckSession()
    controller = motion.GoToGoal((1.0, 0.0), LIMITS)
    with pytest.raises(Blocked, match=r"tb: blocked near \(0\.0, 0\.0\)"):
        drive(session, controller, limit_s=10.0, blocked_s=0.3)
    assert session.sent[-1] == "halt"
    assert any(isinstance(c, tuple) and c[0] > 0 for c in session.sent)  # it was told to drive


def test_without_blocked_detection_only_the_time_limit_ends_it():
    session = StuckSession()
    with pytest.raises(StepFailed) as failure:
        drive(session, motion.GoToGoal((1.0, 0.0), LIMITS), limit_s=0.3)
    assert not isinstance(failure.value, Blocked)
    assert "did not finish within" in str(failure.value)
