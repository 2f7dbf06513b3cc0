"""`manage.py instruct --user NAME [--wait] TEXT` with the real interpreter."""

import pytest
from django.core.management import CommandError, call_command

from execution.models import Instruction
from places.models import Location

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow, pytest.mark.usefixtures("seeded_ontology")]


def test_instruct_wait_prints_transitions_and_outcome(turtle_world, fleet_admin, capsys):
    Location.objects.create(map=Location.objects.first().map, name="Dock", x=-1.6, y=-0.5)
    call_command("instruct", "move turtlebot to Dock", user=fleet_admin.username, wait=True)
    out = capsys.readouterr().out
    assert "turtlebot: ready -> motion  (moving to Dock)" in out
    assert "turtlebot: motion -> ready  (arrived at Dock)" in out
    assert "outcome: succeeded" in out
    instruction = Instruction.objects.get()
    assert instruction.source == "cli" and instruction.user == fleet_admin
    stamps = [
        instruction.received_at,
        instruction.interpreted_at,
        instruction.dispatched_at,
        instruction.first_command_at,
        instruction.motion_started_at,
        instruction.finished_at,
    ]
    assert all(stamps) and stamps == sorted(stamps)


def test_instruct_wait_exits_non_zero_unless_it_succeeds(turtle_world, fleet_admin):
    with pytest.raises(CommandError, match=r"needs_user|refused"):
        call_command("instruct", "move turtlebot to the roof", user=fleet_admin.username, wait=True)


def test_instruct_as_a_viewer_is_refused(turtle_world, viewer):
    with pytest.raises(CommandError, match="may only view"):
        call_command("instruct", "move turtlebot to A", user=viewer.username, wait=True)


def test_instruct_unknown_user(turtle_world):
    with pytest.raises(CommandError, match="no user named 'nobody'"):
        call_command("instruct", "move turtlebot to A", user="nobody")


@pytest.mark.parametrize(
    ("words", "speed"), [("very slowly", "very slow"), ("slowly", "slow"), ("at normal speed", "normal")]
)
def test_instruct_speed_words_drive_the_robot_at_that_speed(turtle_world, fleet_admin, words, speed):
    """Every speed word the interpreter knows runs, and the simulated robot's applied speed stays within it."""
    import threading

    from fleetcore.speed import Limits, pace

    Location.objects.create(map=Location.objects.first().map, name="Dock", x=-1.6, y=-0.5)
    body = turtle_world.fleet.robots["turtlebot"].body
    done, fastest = threading.Event(), [0.0]

    def watch():
        while not done.wait(0.02):
            fastest[0] = max(fastest[0], abs(turtle_world.call(lambda: body.vx)))

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        call_command("instruct", f"move turtlebot {words} to Dock", user=fleet_admin.username, wait=True)
    finally:
        done.set()
        watcher.join(5)
    x, y, _ = turtle_world.call(turtle_world.fleet.robots["turtlebot"].pose)
    assert abs(x - -1.6) < 0.15 and abs(y - -0.5) < 0.15  # it arrived
    robot = Instruction.objects.get().robots.get()
    limit = pace(speed, Limits(robot.max_linear, robot.max_angular)).limits.linear
    assert 0.0 < fastest[0] <= limit * 1.05  # it moved, never faster than the word asked


def test_an_answered_question_closes_keeping_its_type_and_names_what_ran(turtle_world, fleet_admin):
    """Type V "zoom turtlebot to Dock", answered "zoom means move": the question is final, still type V, and
    names the instruction that ran; that one moved the robot."""
    from execution.instructions import submit
    from interpreter import service
    from tests.execution.helpers import wait_final

    Location.objects.create(map=Location.objects.first().map, name="Dock", x=-1.6, y=-0.5)
    question = submit("zoom turtlebot to Dock", fleet_admin)
    assert (question.status, question.type) == ("needs_user", "V")
    service.teach("zoom means move", fleet_admin, question.pk)
    answer = wait_final(submit(question.text, fleet_admin, answer_to=question))
    question.refresh_from_db()
    assert (question.status, question.type) == ("answered", "V")
    assert f"ran as #{answer.pk}" in question.outcome and answer.answer_to_id == question.pk
    assert answer.status == "succeeded", answer.outcome
    x, y, _ = turtle_world.call(turtle_world.fleet.robots["turtlebot"].pose)
    assert abs(x - -1.6) < 0.15 and abs(y - -0.5) < 0.15
