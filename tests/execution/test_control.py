"""Teleoperation and stop from the portal's buttons: leases, limits, audit."""

import pytest

from access.leases import ControlRefused, take
from audit.models import AuditEntry
from execution.control import stop, teleop
from tests.execution.helpers import wait_for

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow]


def test_teleop_publishes_within_the_robot_limits_and_is_audited(turtle_world, operator):
    sim = turtle_world
    v, w = teleop("turtlebot", operator, 5.0, -9.0)
    assert (v, w) == (0.22, -2.84)  # clamped to the registered limits
    command = wait_for(lambda: (c := sim.call(lambda: sim.fleet.robots["turtlebot"].body.cmd)).vx and c)
    assert (command.vx, command.wz) == pytest.approx((0.22, -2.84))
    assert AuditEntry.objects.filter(action="teleop", target="turtlebot", user=operator).exists()
    assert stop(["turtlebot"], operator) == {"turtlebot": "stopped"}
    wait_for(lambda: sim.call(lambda: sim.fleet.robots["turtlebot"].body.cmd).vx == 0.0, what="zero")


def test_a_held_teleop_button_is_audited_once_per_change(turtle_world, operator):
    for _ in range(5):  # a held button repeats the same command at 5 Hz
        teleop("turtlebot", operator, 0.1, 0.0)
    teleop("turtlebot", operator, 0.1, 0.5)
    teleop("turtlebot", operator, 0.0, 0.0)
    audited = AuditEntry.objects.filter(action="teleop", user=operator).order_by("at")
    assert [(e.details["linear"], e.details["angular"]) for e in audited] == [
        (0.1, 0.0),
        (0.1, 0.5),
        (0.0, 0.0),
    ]


def test_teleop_and_stop_respect_leases_and_roles(turtle_world, operator, second_operator, viewer):
    with pytest.raises(ControlRefused, match="may only view"):
        teleop("turtlebot", viewer, 0.1, 0.0)
    with pytest.raises(ControlRefused, match="may only view"):
        stop(["turtlebot"], viewer)
    take(second_operator, turtle_world.robots["turtlebot"])
    with pytest.raises(ControlRefused, match="held by olga"):
        teleop("turtlebot", operator, 0.1, 0.0)
    assert stop(["turtlebot"], operator) == {"turtlebot": "stopped"}  # a lease never blocks a stop


def test_stop_names_unknown_robots(turtle_world, operator):
    with pytest.raises(ValueError, match="No robot named wall-e"):
        stop(["wall-e"], operator)


def test_a_stop_reads_every_robots_bindings_in_one_query_before_its_zeros(
    turtle_world, operator, monkeypatch
):
    """The zeros run in threads, each robot's surface from its bindings: read one query per robot there, a stop
    of a hundred robots spent most of its time on them (docs/scale.md)."""
    import execution.control as control
    from robots.models import Robot

    seen = []
    monkeypatch.setattr(control, "publish_zero", lambda robot: seen.append(robot._prefetched_objects_cache))
    robots = list(Robot.objects.all())  # as a page's stop passes them: rows, nothing prefetched
    assert stop(robots, operator) == dict.fromkeys([r.name for r in robots], "stopped")
    assert seen and all("bindings" in cache for cache in seen)


def test_a_press_reads_no_binding_while_the_robot_and_its_bindings_are_unchanged(turtle_world, operator):
    """teleop_grants keeps each robot's surface in the process and reads it again only when its mark changed."""
    from django.db import connection
    from django.test.utils import CaptureQueriesContext

    from execution.control import teleop_grants

    robot = turtle_world.robots["turtlebot"]
    first = teleop_grants([robot.pk], operator)[robot.pk]
    with CaptureQueriesContext(connection) as queries:
        again = teleop_grants([robot.pk], operator)[robot.pk]
    assert again.surface is first.surface and again.expires > first.expires
    assert not any('"robots_binding"."target"' in q["sql"] for q in queries.captured_queries)
    move = robot.bindings.get(action="move")
    move.target = "/rebound/cmd_vel"
    move.save()  # stamps updated_at, as registration's bulk_update does
    rebound = teleop_grants([robot.pk], operator)[robot.pk]
    assert rebound.surface is not again.surface and rebound.surface.move_topic == "/rebound/cmd_vel"
