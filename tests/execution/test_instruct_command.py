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
