"""A stop holds, on simulated robots judged by their odometry: "stop tiago", then two robots sent to tiago's
place; tiago does not move while they are sent and after, until a person names it again."""

import math
import time

import pytest
from django.utils import timezone

from execution.instructions import submit
from execution.models import Execution, Instruction
from fleetcore import traffic_tuning as tune
from robots.models import Robot
from simworker.testing import running_world
from tests.execution.conftest import register
from tests.execution.helpers import parse, step, wait_final

pytestmark = [pytest.mark.slow]

STILL_M = 0.03  # m: tiago's odometry may wobble this much at rest, no more


@pytest.fixture
def three(executor):
    """turtlebot, husky and tiago of the paper world, registered; twice real time."""
    with running_world("paper", endpoints=["turtlebot", "husky", "tiago"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["turtlebot", "husky", "tiago"])
        yield sim


def drift(sim, home) -> float:
    return math.dist(sim.pose("tiago")[:2], home[:2])


DOOR = (3.0, 4.6)  # the middle of Room 1's 2 m doorway: the only way to D
D = (5.0, 5.0)


@pytest.mark.timeout(300)
def test_a_stopped_robot_stays_put_while_two_are_sent_its_way_until_a_person_names_it(
    three, fleet_admin, monkeypatch
):
    """tiago stops in Room 1's doorway; husky is sent into the room (through the doorway, where it cannot
    pass tiago: before the hold, tiago was asked to make way) and turtlebot to tiago's place. tiago does not
    move while they are sent and after; husky goes by, or gives up saying tiago's stop is in the way. Then a
    person names tiago: that releases it, and it turns."""
    sim = three
    monkeypatch.setattr(tune, "WAIT_LIMIT_S", 25.0)  # husky's stand before it gives up, shortened
    there = submit(
        "tiago to the door", fleet_admin, parse=parse(step(["tiago"], *DOOR, "door", speed="fast"))
    )
    assert wait_final(there, timeout=90).status == "succeeded", there.outcome
    stop = submit("stop tiago", fleet_admin, parse=parse(step(["tiago"], action="stop")))
    assert stop.status == "succeeded", stop.outcome
    home, stopped = sim.pose("tiago"), timezone.now()
    sent = [
        submit("move husky to D", fleet_admin, parse=parse(step(["husky"], *D, "D", speed="normal"))),
        submit("move turtlebot to tiago", fleet_admin, parse=parse(step(["turtlebot"], *home[:2], "tiago"))),
    ]
    farthest, deadline = 0.0, time.monotonic() + 150
    while not all(i.is_final for i in sent) and time.monotonic() < deadline:  # watch tiago while they go
        farthest = max(farthest, drift(sim, home))
        time.sleep(0.2)
        for instruction in sent:
            instruction.refresh_from_db()
    assert all(i.is_final for i in sent), [(i.status, i.outcome) for i in sent]
    husky, turtlebot = sent
    assert husky.status == "succeeded" or "tiago, held by a stop (ada" in husky.outcome, husky.outcome
    assert turtlebot.status == "succeeded", turtlebot.outcome
    time.sleep(2.0)  # and after
    farthest = max(farthest, drift(sim, home))
    assert farthest < STILL_M, farthest
    assert not Execution.objects.filter(robot__name="tiago", created_at__gt=stopped).exists()  # nothing ran
    assert all(i.status == "refused" for i in Instruction.objects.filter(text__startswith="tiago make way"))

    turn = {"action": "turn_by", "robots": ["tiago"], "amount": 90, "destination": None}
    named = wait_final(submit("tiago turn by 90 degrees", fleet_admin, parse=parse(turn)), timeout=60)
    assert (
        named.status == "succeeded" and "tiago released from its hold (held by a stop (ada" in named.outcome
    )
    turned = abs(math.remainder(sim.pose("tiago")[2] - home[2], math.tau))
    assert turned > 1.0 and Robot.objects.get(name="tiago").held_at is None
