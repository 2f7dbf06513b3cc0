"""Move-to-goal (the paper's Figure 7), tasks, poses and the wire messages, without ROS or Django."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetcore import geometry, motion
from fleetcore.motion import GoToGoal, Limits, Rotate
from fleetcore.speed import SPEEDS, UnknownSpeed, pace
from fleetcore.steps import StepError, parse_task

TB3 = Limits(0.22, 2.84)


def simulate(controller, pose, dt=0.05, steps=20000):
    """Integrate a unicycle under the controller's commands (up to 1,000 s: 14 m at "very slow" takes ~330 s)."""
    x, y, yaw = pose
    commands = []
    for _ in range(steps):
        command = controller.command((x, y, yaw))
        commands.append(command)
        if command.done:
            return (x, y, yaw), commands
        x += command.v * math.cos(yaw) * dt
        y += command.v * math.sin(yaw) * dt
        yaw = geometry.wrap(yaw + command.w * dt)
    raise AssertionError("controller did not finish")


def braking(controller, accel: tuple[float, float], gaps: list[float], age: float = 0.05, dt: float = 0.002):
    """A robot whose speeds follow the last command only within its accelerations (m/s², rad/s²), as a real base
    and the simulator's do, commanded at ticks `gaps` apart (cycled: a busy executor's late ticks) on odometry
    `age` seconds old. Integrated until the controller is done and the robot at rest: (yaw turned, distance
    along its start heading) there, and how many commands it took."""
    x = y = yaw = v = w = 0.0
    t, next_tick, ticks, command, done = 0.0, 0.0, 0, motion.Command(0.0, 0.0), False
    seen = [(0.0, (0.0, 0.0, 0.0))]  # (time, pose): what odometry reports `age` later
    turned = 0.0
    while t < 120.0:
        if not done and t >= next_tick:
            pose = next(p for when, p in reversed(seen) if when <= t - age or when == 0.0)
            command = controller.command(pose)
            done = command.done
            next_tick += gaps[ticks % len(gaps)]
            ticks += 1
        v += max(-accel[0] * dt, min(accel[0] * dt, command.v - v))
        w += max(-accel[1] * dt, min(accel[1] * dt, command.w - w))
        x, y = x + v * math.cos(yaw) * dt, y + v * math.sin(yaw) * dt
        yaw, turned = yaw + w * dt, turned + w * dt
        t += dt
        seen.append((t, (x, y, geometry.wrap(yaw))))
        if done and v == 0.0 and w == 0.0:
            return turned, x, ticks
    raise AssertionError("the controller did not bring the robot to rest")


LATE = [0.05, 0.05, 0.05, 0.19]  # every fourth tick 140 ms late, as on the cluster at 100 robots


# (ticks apart, how near it must come to rest): on time (20 Hz; 10 Hz, the executor's rate: link.CONTROL_MS) or every
# fourth late, within the tolerance and what it coasts; a command every 0.1 then 0.3 s, within what a late
# correction at its slowest may overshoot
TURN_TICKS = [([0.05], 3.0), ([0.1], 3.0), (LATE, 3.0), ([0.1, 0.3], 8.0)]
MOVE_TICKS = [([0.05], 0.04), ([0.1], 0.04), (LATE, 0.04), ([0.1, 0.3], 0.08)]


@settings(max_examples=60, deadline=None)
@given(st.floats(-360, 360).filter(lambda d: abs(d) > 5), st.sampled_from(TURN_TICKS))
def test_a_turn_by_an_angle_comes_to_rest_at_it_though_the_robot_brakes_slowly_and_ticks_come_late(
    degrees, ticks
):
    """A TurtleBot brakes at 3.2 rad/s² (its simulated controller's limit): told to stop only once within the
    tolerance, it was still turning at 1.2 rad/s and came to rest 13 degrees past 90 (22 past 360 with every
    command on time, in this model)."""
    gaps, within = ticks
    controller = motion.TurnBy(math.radians(degrees), TB3)
    turned, _, _ = braking(controller, (2.5, 3.2), gaps)
    assert math.degrees(turned) == pytest.approx(degrees, abs=within)
    assert controller.done((0.0, 0.0, geometry.wrap(turned))) == pytest.approx(
        turned, abs=1e-6
    )  # what it says


@settings(max_examples=40, deadline=None)
@given(st.floats(-3, 3).filter(lambda d: abs(d) > 0.05), st.sampled_from(MOVE_TICKS))
def test_a_move_by_a_distance_comes_to_rest_at_it_though_the_robot_brakes_slowly_and_ticks_come_late(
    metres, ticks
):
    gaps, within = ticks
    husky = Limits(1.0, 2.0)  # a Husky's top speed, braking at 1 m/s² (0.5 m from full speed)
    controller = motion.Straight(metres, husky)
    _, along, _ = braking(controller, (1.0, 3.0), gaps)
    assert along == pytest.approx(metres, abs=within)
    assert controller.done((along, 0.0, 0.0)) == pytest.approx(along, abs=1e-6)  # what it says


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi), st.floats(-5, 5), st.floats(-5, 5),
    st.sampled_from([None, *SPEEDS]),
)  # fmt: skip
def test_go_to_goal_arrives_within_tolerance_and_limits(x, y, yaw, gx, gy, speed):
    driven = pace(speed, TB3).limits
    controller = GoToGoal((gx, gy), driven)
    (fx, fy, _), commands = simulate(controller, (x, y, yaw))
    assert math.hypot(fx - gx, fy - gy) < motion.TOLERANCE
    assert all(abs(c.v) <= driven.linear + 1e-9 and abs(c.w) <= driven.angular + 1e-9 for c in commands)
    assert commands[-1] == motion.STOP


def test_go_to_goal_turns_first_when_the_goal_is_behind():
    command = GoToGoal((-1.0, 0.0), TB3).command((0.0, 0.0, 0.0))
    assert command.v == 0.0
    assert command.w != 0.0


def test_rotate_counts_full_turns_from_odometry():
    controller = Rotate(2, TB3)
    (_, _, _), commands = simulate(controller, (0.0, 0.0, 0.3))
    assert controller.turned == pytest.approx(4 * math.pi, abs=0.1)
    assert all(c.v == 0.0 for c in commands)


def test_clean_covers_the_square_around_the_location():
    controller = motion.Clean((1.0, 1.0), TB3)
    visited = []
    x, y, yaw, dt = 1.0, 1.0, 0.0, 0.05
    for _ in range(10000):
        command = controller.command((x, y, yaw))
        if command.done:
            break
        x += command.v * math.cos(yaw) * dt
        y += command.v * math.sin(yaw) * dt
        yaw = geometry.wrap(yaw + command.w * dt)
        visited.append((x, y))
    else:
        raise AssertionError("clean did not finish")
    half = motion.CLEAN_SIZE / 2
    for corner in [(1 - half, 1 - half), (1 + half, 1 - half), (1 - half, 1 + half), (1 + half, 1 + half)]:
        assert min(math.dist(corner, p) for p in visited) < 0.15


@pytest.mark.parametrize(
    ("task", "parsed"),
    [
        ("rotate(5)", ("rotate", 5)),
        ("clean", ("clean", 1)),
        ("Rotate ( 2 )", ("rotate", 2)),
        ("rotate(0.25)", ("rotate", 0.25)),
    ],
)
def test_parse_task(task, parsed):
    assert parse_task(task) == parsed


@pytest.mark.parametrize("task", ["dance", "rotate(-1)", "rotate(1000)", "clean(3)", "", None])
def test_parse_task_refuses_unknown_tasks(task):
    with pytest.raises(StepError):
        parse_task(task)


def test_speed_words_and_unknown_speed():
    def linear(word):
        return pace(word, TB3).limits.linear

    assert linear("slow") < linear(None) < linear("fast") <= TB3.linear
    assert pace("very fast", TB3).limits == TB3
    with pytest.raises(UnknownSpeed, match="warp"):
        pace("warp", TB3)


def test_limits_must_be_positive():
    with pytest.raises(ValueError):
        Limits(0.0, 1.0)


def test_map_pose_is_odometry_composed_with_start_pose():
    odom = {"pose": {"pose": {"position": {"x": 1.0, "y": 0.0}, "orientation": geometry.quaternion(0.0)}}}

    def map_pose(start):  # as the pose hub composes them (robots/poses.py)
        return geometry.compose(geometry.start_offset(start), geometry.pose_of(odom))

    assert map_pose([2.0, 1.0, math.pi / 2]) == pytest.approx((2.0, 2.0, math.pi / 2))
    assert map_pose([]) == pytest.approx((1.0, 0.0, 0.0))


def test_velocity_messages_per_type_and_ros_version():
    assert motion.velocity_message(0.1, 0.2, "geometry_msgs/Twist", 1) == motion.twist(0.1, 0.2)
    ros1 = motion.velocity_message(0.1, 0.2, "geometry_msgs/TwistStamped", 1, 12.5)
    assert ros1["header"]["stamp"] == {"secs": 12, "nsecs": 500000000}
    assert ros1["twist"]["angular"]["z"] == 0.2
    ros2 = motion.velocity_message(0.1, 0.2, "geometry_msgs/msg/TwistStamped", 2, 12.5)
    assert ros2["header"]["stamp"] == {"sec": 12, "nanosec": 500000000}
    with pytest.raises(ValueError, match="PoseStamped"):
        motion.velocity_message(0.1, 0.2, "geometry_msgs/PoseStamped", 1)


def test_navigation_goal_messages():
    goal = motion.move_base_goal(1.0, 2.0, math.pi, "g1", 3.0)
    assert goal["goal_id"]["id"] == "g1"
    assert goal["goal"]["target_pose"]["pose"]["position"] == {"x": 1.0, "y": 2.0, "z": 0.0}
    assert goal["goal"]["target_pose"]["header"]["frame_id"] == "map"
    nav2 = motion.navigate_to_pose_goal(1.0, 2.0, 0.0, 3.0)
    assert nav2["pose"]["header"]["stamp"] == {"sec": 3, "nanosec": 0}
    status = {"status_list": [{"goal_id": {"id": "g0"}, "status": 3}, {"goal_id": {"id": "g1"}, "status": 1}]}
    assert motion.move_base_outcome(status, "g1") == "active"
    assert motion.move_base_outcome(status, "g0") == "succeeded"
    assert motion.move_base_outcome(status, "g9") is None


@pytest.mark.parametrize(("start", "goal"), [(0.0, 1.5), (0.3, -2.8), (3.0, -3.0), (-1.0, -1.0)])
def test_face_turns_the_short_way_to_the_heading_and_stops(start, goal):
    controller = motion.Face(goal, TB3)
    (_, _, yaw), commands = simulate(controller, (1.0, 2.0, start))
    assert abs(geometry.wrap(yaw - goal)) <= controller.tolerance + 0.01
    assert all(c.v == 0.0 for c in commands)
    turns = {math.copysign(1, c.w) for c in commands if c.w}
    assert len(turns) <= 1  # one way round, never back and forth
    if turns:
        assert turns == {math.copysign(1, geometry.wrap(goal - start))}  # the short way


def test_a_destination_keeps_its_heading_and_refuses_a_bad_one():
    from fleetcore.steps import Destination

    assert Destination.from_dict({"name": "", "x": 1, "y": 2, "yaw": 1.5}).yaw == 1.5
    assert Destination.from_dict({"name": "A", "x": 1, "y": 2}).yaw is None
    for bad in ("north", float("nan"), True):
        with pytest.raises(StepError, match="yaw"):
            Destination.from_dict({"name": "", "x": 1, "y": 2, "yaw": bad})


def test_a_robot_clock_rate_is_read_from_its_stamps_and_bad_stamps_change_nothing():
    clock = motion.ClockRate()
    assert clock.rate == 1.0 and not clock.measured
    for i in range(40):  # a simulator at 2x: 0.05 s of wall time per 0.1 s of its stamps
        clock.update(
            100.0 + 0.05 * i, motion.stamp_of({"header": {"stamp": {"sec": 7, "nanosec": i * 10**8}}})
        )
    assert clock.measured and clock.rate == pytest.approx(2.0)
    ros1 = {"header": {"seq": 1, "stamp": {"secs": 3, "nsecs": 5 * 10**8}}}
    assert motion.stamp_of(ros1) == 3.5
    for garbage in (
        {},
        {"header": "x"},
        {"header": {"stamp": {"sec": "1"}}},
        {"header": {"stamp": None}},
        [],
    ):
        assert motion.stamp_of(garbage) is None
        clock.update(200.0, motion.stamp_of(garbage))
    assert clock.rate == pytest.approx(2.0)
    clock.update(300.0, 1.0)  # the stamps jumped back (a restarted robot): a new span, the rate kept
    clock.update(310.0, 1.0 + 10 * 1000.0)  # 1000x: not believable, ignored
    assert clock.rate == pytest.approx(2.0)
