"""A running instruction whose robot is stopped while the database refuses writes ends as failed with that reason
(issue 30, item 5): its runner halts the robot and keeps the end's words in Redis; once the database takes writes
again the watchdog's sweep records them ("stopped; the database is locked ..."), not "executor lost"."""

import pytest
from django.db import connection

from alerts.models import Alert
from execution import coordination, watchdog
from execution.control import stop
from execution.instructions import submit
from execution.models import Execution, Instruction
from tests.execution.faults import DatabaseLock
from tests.execution.helpers import at_rest, parse, step, transitions, wait_for, without_command_timeout

pytestmark = [pytest.mark.timeout(90)]


@pytest.fixture
def short_lock_wait(monkeypatch):
    """The runners' connections (opened in their threads from now on) wait 2 s for a locked database (SQLite's
    busy timeout, PostgreSQL's lock_timeout), not 20 s or for good."""
    if connection.vendor == "sqlite":
        monkeypatch.setitem(connection.settings_dict["OPTIONS"], "timeout", 2)
    else:
        monkeypatch.setitem(connection.settings_dict["OPTIONS"], "options", "-c lock_timeout=2000")


def test_a_stop_the_database_cannot_record_is_settled_with_its_reason(
    turtle_world, short_lock_wait, fleet_admin
):
    sim = turtle_world
    without_command_timeout(sim, "turtlebot")
    instruction = submit(
        "move turtlebot far", fleet_admin, parse=parse(step(["turtlebot"], 0.5, -0.5, "far"))
    )
    wait_for(lambda: Instruction.objects.get(pk=instruction.pk).motion_started_at, 40, "motion")
    execution = Execution.objects.get(instruction=instruction)
    lock = DatabaseLock(connection.settings_dict)
    lock.take()
    try:
        results = stop(["turtlebot"], fleet_admin)  # the zero and the flag; its own records refused, and said
        assert results["turtlebot"] == "stopped" and "the database is locked" in results.note()
        kept = wait_for(lambda: coordination.unrecorded_ends([execution.pk]), 20, "the end kept in Redis")
        assert kept[execution.pk].startswith("stopped; the database is locked")
        wait_for(lambda: at_rest(sim, "turtlebot"), 10, "the robot at rest")
        assert Execution.objects.get(pk=execution.pk).status == "running"  # nothing could record it yet
    finally:
        lock.close()
    wait_for(
        lambda: coordination.lock_holders([execution.robot_id])[execution.robot_id] is None,
        10,
        "the runner gone",
    )
    assert watchdog.recover() == [execution.pk]  # the sweep, now that the database takes writes
    execution.refresh_from_db()
    assert (execution.status, execution.error) == ("failed", kept[execution.pk])
    instruction.refresh_from_db()
    assert instruction.status == "failed" and "stopped; the database is locked" in instruction.outcome
    assert transitions("turtlebot")[-1][2].startswith("stopped; the database is locked")
    assert not Alert.objects.filter(kind="executor_lost").exists()  # no executor was lost
    assert coordination.unrecorded_ends([execution.pk]) == {}
    assert at_rest(sim, "turtlebot")
