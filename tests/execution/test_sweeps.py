"""Nothing stays unfinished: each non-final status has a sweep with a deadline (execution/sweeps.py)."""

from datetime import timedelta

import pytest
from django.utils import timezone

from execution import sweeps
from execution.models import Execution, Instruction
from robots.models import Robot

pytestmark = pytest.mark.django_db


@pytest.fixture
def robot():
    return Robot.objects.create(name="tb", endpoint="ws://127.0.0.1:1", link_status=Robot.Link.ONLINE)


def ago(seconds: float):
    return timezone.now() - timedelta(seconds=seconds)


def instruction(status: str, age: float, **fields) -> Instruction:
    return Instruction.objects.create(text="move tb to A", status=status, received_at=ago(age), **fields)


def test_a_received_instruction_a_minute_old_fails_and_a_fresh_one_is_left(robot):
    stale, fresh = instruction("received", sweeps.RECEIVED_S + 5), instruction("received", 5)
    assert sweeps.sweep()["received"] == [stale.pk]
    stale.refresh_from_db(), fresh.refresh_from_db()
    assert (stale.status, stale.outcome) == ("failed", sweeps.NOT_DISPATCHED)
    assert stale.finished_at is not None
    assert fresh.status == "received"


def test_an_unanswered_question_expires_with_a_note_its_robot_leaves_the_dialog_and_progress(robot, settings):
    from fleetcore.states import Event

    settings.FLEET_QUESTION_EXPIRY_SECONDS = 600
    Robot.objects.filter(pk=robot.pk).update(state=Robot.State.READY)
    old = instruction("needs_user", 605, interpreted_at=ago(605), outcome="Which robot?")
    Robot.objects.transition(robot.pk, Event.ASK, "Which robot?", old)
    recent = instruction("needs_user", 5, interpreted_at=ago(5))
    assert sweeps.sweep()["needs_user"] == [old.pk]  # the scheduler runs the sweeps every SLOW_S
    old.refresh_from_db(), recent.refresh_from_db(), robot.refresh_from_db()
    assert (old.status, old.outcome) == ("cancelled", "Which robot? (expired: no answer within 10 min)")
    assert old.expired and not recent.expired and recent.status == "needs_user"
    assert robot.state == Robot.State.READY
    assert list(Instruction.objects.in_progress_list()) == [recent]  # the console's Progress list drops it


def test_the_question_expiry_is_a_setting(robot, settings):
    settings.FLEET_QUESTION_EXPIRY_SECONDS = 90
    waited = instruction("needs_user", 95, interpreted_at=ago(95))
    assert sweeps.sweep()["needs_user"] == [waited.pk]
    assert Instruction.objects.get(pk=waited.pk).outcome.endswith("(expired: no answer within 90 s)")


def test_work_queued_for_a_robot_offline_too_long_fails_and_settles_its_instruction(robot):
    queued = instruction("queued", 60)
    execution = Execution.objects.create(instruction=queued, robot=robot, steps=[{"action": "move"}])
    Robot.objects.filter(pk=robot.pk).update(link_status=Robot.Link.ONLINE, last_seen=ago(600))
    assert sweeps.sweep()["offline"] == []  # online: it waits for its runner
    Robot.objects.filter(pk=robot.pk).update(link_status=Robot.Link.OFFLINE, last_seen=ago(5))
    assert sweeps.sweep()["offline"] == []  # offline for a moment: the link may come back
    Robot.objects.filter(pk=robot.pk).update(last_seen=ago(sweeps.OFFLINE_S + 5))
    assert sweeps.sweep()["offline"] == [execution.pk]
    execution.refresh_from_db(), queued.refresh_from_db()
    assert execution.status == "failed" and execution.error.startswith("robot offline")
    assert queued.status == "failed" and "robot offline" in queued.outcome


def test_a_preempted_execution_of_an_offline_robot_fails_too(robot):
    running = instruction("running", 60)
    execution = Execution.objects.create(instruction=running, robot=robot, status="preempted")
    Robot.objects.filter(pk=robot.pk).update(
        link_status=Robot.Link.OFFLINE, last_seen=ago(sweeps.OFFLINE_S + 5)
    )
    assert sweeps.sweep()["offline"] == [execution.pk]
    assert Instruction.objects.get(pk=running.pk).status == "failed"


def test_an_instruction_whose_executions_all_ended_is_settled(robot):
    lost = instruction("running", 30)
    Execution.objects.create(instruction=lost, robot=robot, status="succeeded")
    going = instruction("running", 30)
    Execution.objects.create(instruction=going, robot=robot, status="running")
    assert sweeps.sweep()["unsettled"] == [lost.pk]
    assert Instruction.objects.get(pk=lost.pk).status == "succeeded"
    assert Instruction.objects.get(pk=going.pk).status == "running"  # its runner (or the watchdog) owns it


def test_a_queued_instruction_without_any_execution_fails_after_the_deadline(robot):
    empty, fresh = instruction("queued", sweeps.RECEIVED_S + 5), instruction("queued", 1)
    assert sweeps.sweep()["unsettled"] == [empty.pk]
    assert Instruction.objects.get(pk=empty.pk).status == "failed"
    assert Instruction.objects.get(pk=fresh.pk).status == "queued"


def test_after_the_sweeps_only_owned_statuses_remain(robot):
    """Every non-final status either has its owner (a fresh row, a live runner) or has been finished."""
    instruction("received", sweeps.RECEIVED_S + 5)
    instruction("needs_user", sweeps.answer_s() + 5, interpreted_at=ago(sweeps.answer_s() + 5))
    instruction("queued", sweeps.RECEIVED_S + 5)
    sweeps.sweep()
    assert not Instruction.objects.open().exists()
    assert Instruction.objects.final().count() == 3
