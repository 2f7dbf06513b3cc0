"""An instruction to many robots is stored and dispatched in the same queries as one to two (each robot's state is
read with the others' and their executions inserted together), and its pushes go to the loop in one hand-over. A query or two per robot made the POST of
"turn left 720 degrees" to 50 robots take 1.2 to 1.9 s on the cluster at 500 robots, so its ten instructions went
out over 12 s and never had the fleet turning at once (docs/scale.md)."""

import pytest
from django.db import connection
from django.test.utils import CaptureQueriesContext

from execution.instructions import submit
from execution.models import Execution
from robots.models import Robot
from tests.execution.helpers import parse, wait_final

pytestmark = [pytest.mark.timeout(90)]

# "turn left 5 degrees" as the interpreter reads it, to the robots selected on the page (the ontology's terms may
# have been flushed by an earlier transactional test in the same process)
TURN = parse({"action": "turn_by", "robots": "any", "amount": 5, "destination": None, "speed": None})


def _submitted(user, robot_ids) -> int:
    """The queries of one instruction to these robots (all ready), checked to have queued one execution each."""
    with CaptureQueriesContext(connection) as queries:
        instruction = submit("turn left 5 degrees", user, parse=TURN, robot_ids=robot_ids)
    assert instruction.status == "queued", instruction.outcome
    executions = Execution.objects.filter(instruction=instruction)
    assert sorted(executions.values_list("robot_id", flat=True)) == sorted(robot_ids)
    return len(queries.captured_queries)


def test_the_queries_of_an_instruction_do_not_grow_with_its_robots(demo_world, fleet_admin):
    ids = list(Robot.objects.order_by("pk").values_list("pk", flat=True))
    woken = submit(
        "turn left 5 degrees", fleet_admin, parse=TURN, robot_ids=ids
    )  # every robot woken (registered -> ready)
    assert Execution.objects.filter(instruction=woken).count() == len(ids)
    assert wait_final(woken, timeout=40).status == "succeeded", woken.outcome
    assert set(Robot.objects.values_list("state", flat=True)) == {Robot.State.READY}
    assert _submitted(fleet_admin, ids[2:7]) == _submitted(fleet_admin, ids[:2])


def test_the_pushes_of_an_instruction_go_to_the_loop_in_one_hand_over(demo_world, fleet_admin, monkeypatch):
    """From a thread with no loop of its own (a web request's), each push after the commit was a hand-over to
    the server's loop and a wait; the instruction and every robot's task list now go together (live.together),
    each group's in one message."""
    import live

    ids = list(Robot.objects.order_by("pk").values_list("pk", flat=True))
    handed = []
    real = live.async_to_sync
    monkeypatch.setattr(live, "async_to_sync", lambda fn: handed.append(fn.__name__) or real(fn))
    instruction = submit("turn left 5 degrees", fleet_admin, parse=TURN, robot_ids=ids[:5])
    assert instruction.status == "queued", instruction.outcome
    assert handed == ["_send_each"]  # one hand-over, not one per push
