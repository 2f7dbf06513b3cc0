"""The pose gate: NaN, infinities, jumps faster than the robot and stamps from the future are refused."""

import math

import pytest

from fleetcore.posegate import SETTLE_S, InvalidOdometry, PoseGate


def odom(x, y=0.0, stamp=100.0, v=0.0, qz=0.0, qw=1.0):
    return {
        "header": {"stamp": {"sec": int(stamp), "nanosec": int((stamp % 1) * 1e9)}},
        "pose": {"pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": {"z": qz, "w": qw}}},
        "twist": {"twist": {"linear": {"x": v}, "angular": {"z": 0.0}}},
    }


@pytest.mark.parametrize(
    ("message", "reason"),
    [
        (odom(math.nan), "x is NaN"),
        (odom(0.0, math.inf), "y is inf"),
        (odom(0.0, -math.inf), "y is -inf"),
        (odom(0.0, qz=math.nan), "orientation z is NaN"),
        (odom(0.0, v=math.nan), "linear speed is NaN"),
    ],
)
def test_non_finite_numbers_are_refused_with_the_field_named(message, reason):
    gate = PoseGate(max_linear=1.0)
    gate.admit(odom(0.0), 1000.0)
    with pytest.raises(InvalidOdometry, match=reason):
        gate.admit(message, 1000.1)
    assert gate.fault == reason and gate.since == 1000.1


def test_a_good_message_clears_the_flag():
    gate = PoseGate(max_linear=1.0)
    with pytest.raises(InvalidOdometry):
        gate.admit(odom(math.nan), 1000.0)
    assert gate.admit(odom(0.1, stamp=100.1), 1000.1).pose[0] == pytest.approx(0.1)
    assert gate.fault is None and gate.since is None


def test_a_jump_faster_than_the_robot_is_refused_and_a_spike_ends_in_line():
    gate = PoseGate(max_linear=1.0)
    gate.admit(odom(0.0, stamp=100.0), 1000.0)
    gate.admit(odom(0.05, stamp=100.05), 1000.05)  # 1 m/s: in line
    with pytest.raises(InvalidOdometry, match=r"jumped 1000\.0 m in 0\.05 s, faster than its 1 m/s"):
        gate.admit(odom(1000.05, stamp=100.1), 1000.1)
    gate.admit(odom(0.15, stamp=100.15), 1000.15)  # back in line with the last good pose
    assert gate.fault is None


def test_a_jump_that_stays_is_taken_after_it_settles():
    gate = PoseGate(max_linear=1.0)
    gate.admit(odom(0.0, stamp=100.0), 1000.0)
    t = 0.1
    with pytest.raises(InvalidOdometry):
        gate.admit(odom(500.0, stamp=100.0 + t), 1000.0 + t)
    while t < SETTLE_S - 0.1:  # still in the new place, moving nowhere: refused until it has settled
        t += 0.1
        with pytest.raises(InvalidOdometry, match="jumped"):
            gate.admit(odom(500.0, stamp=100.0 + t), 1000.0 + t)
    t += 0.3
    assert gate.admit(odom(500.0, stamp=100.0 + t), 1000.0 + t).pose[0] == 500.0
    assert gate.fault is None


def test_a_robot_at_its_top_speed_passes():
    gate = PoseGate(max_linear=1.5)
    for i in range(50):
        gate.admit(odom(1.5 * i * 0.05, stamp=100.0 + i * 0.05), 1000.0 + i * 0.05)
    assert gate.fault is None


def test_a_stamp_from_the_future_is_refused():
    gate = PoseGate(max_linear=1.0)
    gate.admit(odom(0.0, stamp=100.0), 1000.0)
    with pytest.raises(InvalidOdometry, match=r"stamp from the future \(3598 s ahead of its clock\)"):
        gate.admit(odom(0.0, stamp=3700.0), 1000.1)


def test_a_default_filled_message_is_refused_and_the_next_good_one_taken():
    """A bridge completes an empty message with defaults (stamp 0, at the origin): taken as good, it made the next
    real frame look 100 s in the future and failed the robot's trip on one hostile frame."""
    gate = PoseGate(max_linear=1.0)
    gate.admit(odom(0.3, stamp=100.0), 1000.0)
    with pytest.raises(InvalidOdometry, match=r"stamp went back 100.0 s"):
        gate.admit(odom(0.0, stamp=0.0), 1005.0)
    assert gate.admit(odom(0.31, stamp=100.05), 1005.05).pose[0] == pytest.approx(0.31)
    assert gate.fault is None


def test_a_first_stamp_far_ahead_of_our_clock_is_refused():
    gate = PoseGate(max_linear=1.0)
    with pytest.raises(InvalidOdometry, match="stamp from the future"):
        gate.admit(odom(0.0, stamp=4_000_000_000.0), 1_700_000_000.0)


def test_a_fast_simulator_clock_is_not_the_future():
    gate = PoseGate(max_linear=1.0)
    for i in range(20):  # the robot's clock runs 4 times as fast as ours
        gate.admit(odom(0.0, stamp=100.0 + i * 0.4), 1000.0 + i * 0.1)
    assert gate.fault is None
