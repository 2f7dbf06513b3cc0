"""The pymunk physics: limits, command timeout, walls, laser."""

import math

import pytest

from fleetcore.catalog import model
from fleetcore.world import load_world
from simworker.physics import Physics


@pytest.fixture
def physics():
    """An empty paper world with no robots yet."""
    return Physics(load_world("paper").map)


def run(physics, seconds, robot=None, cmd=None):
    for i in range(round(seconds / physics.dt)):
        if robot is not None and cmd is not None and i % 5 == 0:
            robot.command(*cmd)
        physics.step()


def test_robot_accelerates_within_the_limit_to_the_commanded_speed(physics):
    tb = physics.add_robot("tb", model("turtlebot3_burger"), -2.0, -0.5, 0.0)
    tb.command(0.2, 0.0)
    physics.step()
    assert tb.twist()[0] == pytest.approx(2.5 * physics.dt)  # acc_lim_x 2.5 m/s^2
    run(physics, 1.0, tb, (0.2, 0.0))
    assert tb.twist()[0] == pytest.approx(0.2)
    assert tb.pose()[0] > -2.0 + 0.19


def test_commands_are_clamped_to_the_controller_limits(physics):
    tb = physics.add_robot("tb", model("turtlebot3_burger"), -2.0, -0.5, 0.0)
    run(physics, 1.0, tb, (5.0, 0.0))
    assert tb.twist()[0] == pytest.approx(0.22)


def test_robot_stops_after_the_command_times_out(physics):
    tb = physics.add_robot("tb", model("turtlebot3_burger"), -2.0, -0.5, 0.0)
    tb.command(0.2, 0.0)
    run(physics, 1.0)
    assert tb.twist()[0] == pytest.approx(0.0)
    assert 0.05 < tb.pose()[0] + 2.0 < 0.12  # moved only until the 0.5 s timeout


def test_robot_driven_at_a_wall_stops_at_it(physics):
    husky = physics.add_robot("h", model("husky"), -4.0, -1.0, math.pi)  # facing the west wall at x = -6
    run(physics, 6.0, husky, (1.0, 0.0))
    x = husky.pose()[0]
    assert x - 0.4937 >= -6.0 - 0.02  # its front never enters the wall
    assert x < -5.4  # it got there
    run(physics, 1.0, husky, (1.0, 0.0))
    assert husky.pose()[0] == pytest.approx(x, abs=0.01)  # and stays, still commanded


def test_robots_collide_with_each_other(physics):
    a = physics.add_robot("a", model("tiago"), 0.0, -1.5, 0.0)
    b = physics.add_robot("b", model("husky"), 1.5, -1.5, 0.0)
    run(physics, 3.0, a, (0.5, 0.0))
    assert b.pose()[0] - a.pose()[0] >= 0.275 + 0.4937 - 0.05


def test_legged_robot_moves_sideways(physics):
    spot = physics.add_robot("s", model("spot"), 4.0, 1.5, 0.0)
    run(physics, 1.0, spot, (0.0, 0.0, 0.3))
    assert spot.pose()[1] > 1.5 + 0.2


def test_laser_sees_the_wall_and_reports_none_out_of_range(physics):
    tb = physics.add_robot("tb", model("turtlebot3_burger"), -5.0, -1.5, 0.0)
    ranges = physics.scan(tb, model("turtlebot3_burger").laser)
    assert len(ranges) == 360
    assert ranges[180] == pytest.approx(1.0, abs=0.03)  # facing west: the wall at x = -6
    assert ranges[0] is None  # east: nothing within 3.5 m


def test_robot_robot_contacts_are_counted_with_who_touched_whom(physics):
    a = physics.add_robot("a", model("tiago"), 0.0, -1.5, 0.0)
    physics.add_robot("b", model("husky"), 1.5, -1.5, 0.0)
    physics.add_robot("far", model("turtlebot3_burger"), -4.0, 4.0, 0.0)
    run(physics, 1.0)
    assert physics.contacts == []  # standing apart: nothing touches
    run(physics, 3.0, a, (0.5, 0.0))
    assert [(c.a, c.b) for c in physics.contacts] == [("a", "b")]  # one touch, still pressed: not recounted
    assert 0.0 < physics.contacts[0].t <= physics.time


def test_a_robot_at_a_wall_is_no_contact(physics):
    husky = physics.add_robot("h", model("husky"), -4.0, -1.0, math.pi)
    run(physics, 6.0, husky, (1.0, 0.0))
    assert husky.pose()[0] < -5.4 and physics.contacts == []


def test_a_fleet_that_keeps_the_last_command_drives_on_without_one():
    """`simworker --keep-last-command`: bases without a cmd_vel timeout, for the chaos tests."""
    from simworker.fleet import SimFleet

    fleet = SimFleet("paper", endpoints=["turtlebot"], keep_last_command=True)
    tb = fleet.physics.robots["turtlebot"]
    tb.command(0.2, 0.0)
    run(fleet.physics, 1.0)
    assert tb.twist()[0] == pytest.approx(0.2)  # still driving long after the model's 0.5 s timeout


def _plain_drive(robot):
    """The drive as first written (clamp calls, rotation_vector), kept here as the reference for the faster one."""

    def clamp(value, low, high):
        return low if value < low else high if value > high else value

    def drive(body, gravity, damping, dt):
        p, cmd = robot.profile, robot.cmd
        if robot.physics.time - cmd.stamp > p.cmd_timeout:
            tx = ty = tw = 0.0
        else:
            tx, ty, tw = cmd.vx, cmd.vy, cmd.wz
        dv, dw = p.acc_v * dt, p.acc_w * dt
        robot.vx += clamp(tx - robot.vx, -dv, dv)
        robot.vy += clamp(ty - robot.vy, -dv, dv)
        robot.wz += clamp(tw - robot.wz, -dw, dw)
        c, s = body.rotation_vector
        body.velocity = (robot.vx * c - robot.vy * s, robot.vx * s + robot.vy * c)
        body.angular_velocity = robot.wz

    return drive


def test_the_drive_moves_robots_as_the_plain_ramp_does():
    """simworker.physics drives each awake robot through a velocity callback at every step; the one kept is
    written for speed. The same commands (ramps, turns, sideways, a reversal, a timeout) end on the same
    poses as the plain ramp's, to a micrometre."""
    worlds = [Physics(load_world("paper").map) for _ in range(2)]
    fleets = []
    for world in worlds:
        fleets.append(
            [
                world.add_robot("tb", model("turtlebot3_burger"), -2.0, -0.5, 0.3),
                world.add_robot("dog", model("spot"), 0.5, 1.0, -1.0),
            ]
        )
    for robot in fleets[1]:
        robot.body.velocity_func = _plain_drive(robot)
    plan = [((0.2, 1.0, 0.0), (0.5, 0.0, 0.3)), ((-0.1, -2.0, 0.0), (0.0, 0.5, 0.2)), (None, None)]
    for step in range(600):
        for fleet in fleets:
            for robot, cmd in zip(fleet, plan[min(step // 150, 2)], strict=True):
                if cmd is not None and step % 5 == 0:
                    robot.command(*cmd)
        for world in worlds:
            world.step()
    for fast, plain in zip(*fleets, strict=True):
        assert fast.pose() == pytest.approx(plain.pose(), abs=1e-6)
        assert fast.twist() == pytest.approx(plain.twist(), abs=1e-6)


def test_robots_at_rest_fall_asleep_and_a_command_wakes_them(physics):
    """A resting body costs the simulator nothing only once Chipmunk puts it to sleep: the drive must not write
    a velocity to a body at rest (Chipmunk's setters wake it). Once asleep, a command wakes it and it drives."""
    still = physics.add_robot("still", model("turtlebot3_burger"), -2.0, -0.5, 0.0)
    turned = physics.add_robot("turned", model("turtlebot3_burger"), 0.5, 1.0, 0.0)
    turned.command(0.0, 1.0)  # times out after 0.5 s, ramps down, then rests
    run(physics, 2.5)
    assert still.body.is_sleeping and turned.body.is_sleeping
    at_rest = turned.pose()
    run(physics, 1.0, turned, (0.0, 1.0))
    assert not turned.body.is_sleeping
    assert abs(turned.pose()[2] - at_rest[2]) > 0.5  # it turned under the command
    assert still.body.is_sleeping


def test_a_resting_robot_pushed_by_another_is_woken_and_does_not_slide_on(physics):
    """Nothing slows a body in a top-down world but the drive: a robot at rest that is shoved must be set
    back to rest, not left gliding with the push (and the touch wakes it from its sleep)."""
    pusher = physics.add_robot("pusher", model("turtlebot3_burger"), -2.0, -0.5, 0.0)
    resting = physics.add_robot("resting", model("turtlebot3_burger"), -1.6, -0.5, 0.0)
    run(physics, 1.5)
    assert resting.body.is_sleeping
    run(physics, 2.0, pusher, (0.2, 0.0))  # drives into it
    assert physics.contacts, "the pusher never reached the resting robot"
    run(physics, 1.0)  # the pusher's command times out and it stops
    after_push = resting.pose()
    run(physics, 2.0)
    assert resting.pose() == pytest.approx(after_push, abs=1e-3)
    assert resting.twist() == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
