"""Cancel one instruction: waiting work dropped at once, a running one stopped with its robot at rest (odometry),
settled as cancelled by whom, audited; the roles' rules (execution/tasklist.py, access.leases.check_cancel)."""

import math

import pytest
from django.core.management import call_command

from access.leases import ControlRefused, take
from audit.models import AuditEntry
from execution import tasklist
from execution.instructions import submit
from execution.models import Execution, Instruction
from robots.models import Robot
from tests.execution.helpers import at_rest, parse, step, wait_final, wait_for


def _queued(robot, user, text="move husky to A"):
    """An instruction of `user` waiting in the robot's queue (no runner: nothing picks it up)."""
    instruction = Instruction.objects.create(text=text, user=user, status=Instruction.Status.QUEUED)
    Execution.objects.create(instruction=instruction, robot=robot, steps=[step([robot.name], 1, 1)])
    instruction.robots.set([robot])
    return instruction


@pytest.fixture
def husky(db):
    return Robot.objects.create(name="husky", model="husky", drive="wheeled", endpoint="ws://127.0.0.1:1")


def test_a_waiting_instruction_is_cancelled_with_who_and_audited(husky, operator, settings):
    settings.FLEET_EXEC_KEY_PREFIX = "test:cancel:waiting"
    instruction = _queued(husky, operator)
    done = tasklist.cancel_instruction(instruction.pk, operator, source="api")
    assert done.status == "cancelled" and "cancelled by otto" in done.outcome
    assert Execution.objects.get(instruction=done).status == "cancelled"
    entry = AuditEntry.objects.get(action="cancel")
    assert (entry.user, entry.target, entry.details["source"]) == (operator, f"#{done.pk}", "api")
    with pytest.raises(tasklist.NothingToCancel, match="already over"):
        tasklist.cancel_instruction(done.pk, operator)


def test_roles_a_viewer_never_an_operator_others_unless_held_an_admin_always(
    husky, operator, second_operator, viewer, fleet_admin
):
    mine = _queued(husky, operator)
    with pytest.raises(ControlRefused, match="may only view"):
        tasklist.cancel_instruction(mine, viewer)
    take(operator, husky)  # otto holds husky: olga may not take back otto's work on it
    with pytest.raises(ControlRefused, match="held by otto"):
        tasklist.cancel_instruction(mine, second_operator)
    assert tasklist.cancel_instruction(mine, operator).status == "cancelled"  # her own, always
    theirs = _queued(husky, second_operator)
    assert tasklist.cancel_instruction(theirs, operator).status == "cancelled"  # she holds the robot
    system = _queued(husky, None)
    assert tasklist.cancel_instruction(system, fleet_admin).status == "cancelled"


def test_a_question_is_cancelled_as_it_is(db, operator):
    question = Instruction.objects.create(text="move husky to the roof", user=operator, status="needs_user")
    done = tasklist.cancel_instruction(question, operator)
    assert done.status == "cancelled" and "cancelled by otto" in done.outcome


@pytest.mark.slow
@pytest.mark.timeout(90)
@pytest.mark.usefixtures("seeded_ontology")
def test_cancelling_the_queued_then_the_running_instruction_brings_the_robot_to_rest(turtle_world, operator):
    sim = turtle_world
    far = submit("move turtlebot far", operator, parse=parse(step(["turtlebot"], 0.5, -0.5, "far")))
    behind = submit("move turtlebot back", operator, parse=parse(step(["turtlebot"], -1.7, -0.2, "back")))
    wait_for(lambda: sim.call(lambda: sim.fleet.robots["turtlebot"].body.vx) > 0.05, what="driving")
    assert Execution.objects.get(instruction=behind).status == "queued"

    dropped = tasklist.cancel_instruction(behind, operator)
    assert dropped.status == "cancelled"
    assert Execution.objects.get(instruction=far).status == "running"  # the running one is not touched

    call_command("instruct", f"cancel #{far.pk}", user=operator.username)  # the CLI, through the parser
    far = wait_final(far)
    assert far.status == "cancelled" and "cancelled by otto" in far.outcome
    wait_for(lambda: at_rest(sim, "turtlebot"), what="at rest")
    settled = sim.pose("turtlebot")
    moment = sim.call(lambda: sim.fleet.physics.time)
    wait_for(lambda: sim.call(lambda: sim.fleet.physics.time) >= moment + 1.0, what="one second")
    assert math.dist(settled[:2], sim.pose("turtlebot")[:2]) < 0.01  # odometry: it stays where it stopped
    said = Instruction.objects.get(text=f"cancel #{far.pk}")
    assert said.status == "succeeded" and said.outcome.startswith(
        f"#{far.pk} (move turtlebot far): cancelled"
    )
    assert Robot.objects.get(name="turtlebot").held_at is None  # a cancel is no stop: nothing is held


@pytest.mark.usefixtures("seeded_ontology")
def test_cancel_a_robots_instruction_by_its_name(husky, operator):
    from interpreter import versions

    versions.bump_fleet()
    first, second = _queued(husky, operator), _queued(husky, operator, "move husky to B")
    said = submit("cancel husky's instruction", operator)
    assert said.status == "succeeded", said.outcome
    first.refresh_from_db(), second.refresh_from_db()
    assert (first.status, second.status) == ("cancelled", "queued")  # the first in its queue
    assert submit("cancel #999", operator).outcome == "There is no instruction #999."
