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


def test_a_stops_zeros_get_their_surfaces_read_at_once_and_no_binding_while_nothing_changed(
    turtle_world, operator, monkeypatch
):
    """The zeros run in threads, each robot's surface from its bindings: read one query per robot there, a stop
    of a hundred robots spent most of its time on them, and reading every robot's bindings at each stop a fifth
    of it (docs/scale.md). The surfaces are read together before the zeros, and kept while nothing changed."""
    from django.db import connection
    from django.test.utils import CaptureQueriesContext

    import execution.control as control
    from robots.models import Robot

    seen = []
    monkeypatch.setattr(control, "publish_zero", lambda robot, surface: seen.append((robot.name, surface)))
    robots = list(Robot.objects.all())  # as a page's stop passes them: rows, nothing prefetched
    assert stop(robots, operator) == dict.fromkeys([r.name for r in robots], "stopped")
    assert seen and all(surface is not None and surface.can_move for _, surface in seen)
    with CaptureQueriesContext(connection) as queries:
        assert stop(robots, operator) == dict.fromkeys([r.name for r in robots], "stopped")
    assert not any('"robots_binding"."target"' in q["sql"] for q in queries.captured_queries)
    move = robots[0].bindings.get(action="move")
    move.target = "/rebound/cmd_vel"
    move.save()  # stamps updated_at, as registration's bulk_update does
    seen.clear()
    stop(robots, operator)
    assert dict(seen)[robots[0].name].move_topic == "/rebound/cmd_vel"


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


def test_a_stop_buttons_robots_are_read_without_json_columns_and_no_robot_is_read_again(demo_world, operator):
    """The STOP button's path (portal.consumers.command_stop) reads the robots as their zeros need them: no
    footprint, URDF facts or binding candidates (a fifth of a stop-all's time in the web), and no column left
    out is read back robot by robot (the queries of a stop do not grow with its robots)."""
    from django.db import connection
    from django.test.utils import CaptureQueriesContext

    from portal.consumers import command_stop
    from robots.models import Robot

    ids = sorted(Robot.objects.values_list("pk", flat=True))
    command_stop(
        operator, {"robots": ids[:1]}
    )  # the person's permissions read once, as a socket's first stop does
    counts = []
    for some in (ids[:2], ids[:4]):
        with CaptureQueriesContext(connection) as queries:
            answer = command_stop(operator, {"robots": some})
        assert answer.startswith("Stopped ") and "not reached" not in answer, answer
        sql = [q["sql"] for q in queries.captured_queries]
        assert not [
            q for q in sql if any(col in q for col in ('"footprint"', '"description"', '"candidates"'))
        ]
        counts.append(len(sql))
    assert counts[0] == counts[1], counts
