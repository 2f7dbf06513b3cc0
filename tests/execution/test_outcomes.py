"""What the answer says a robot did is where the simulator has it: outcomes judged from the pose, and a place
for every robot sent to one place at once (issue 31). Ground truth is the simulator's own pose of each body."""

import itertools
import math
import re

import pytest

from execution.instructions import submit
from fleetcore.outcomes import TOLERANCE_M
from fleetcore.traffic import compass
from simworker.testing import running_world
from tests.execution.conftest import register
from tests.execution.helpers import parse, step, wait_each

pytestmark = [pytest.mark.slow]

A = (2.0, 2.0)
FREE = re.compile(r"at a free spot (?P<d>[\d.]+) m (?P<dir>[a-z-]+) of A; A is taken by (?P<by>\w+)")


@pytest.fixture
def paper_world(executor):
    """robot1..4, husky and tiago of the paper world registered, at twice real time."""
    with running_world("paper", endpoints=["robots", "husky", "tiago"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["robots", "husky", "tiago"])
        yield sim


def said_matches_pose(words: str, pose, others: list[str]) -> None:
    """The words of one robot's move to A against where the simulator has it."""
    here = pose[:2]
    if words.startswith("arrived at A"):
        assert math.dist(here, A) <= TOLERANCE_M, (words, here)
        return
    found = FREE.match(words)
    assert found, words
    assert abs(float(found["d"]) - math.dist(here, A)) <= 0.1, (words, here)
    assert found["dir"] == compass(A, here) and found["by"] in others, (words, here)
    assert math.dist(here, A) > TOLERANCE_M


def circumscribed(sim, name) -> float:
    return sim.fleet.robots[name].profile.circumscribed_radius


@pytest.mark.timeout(240)
def test_four_robots_sent_to_one_place_at_once_each_end_on_a_spot_of_their_own(paper_world, fleet_admin):
    """husky, robot1, robot2 and tiago, each sent to A by its own instruction, all at once (the husky first,
    given A itself): every one ends on a spot of its own (judged by the simulator's poses: no two closer than
    their radii), and each answer says where its robot is: at A for one, at a free spot next to it for the
    others, with the distance and direction the simulator has and who took A."""
    sim, names = paper_world, ["husky", "robot1", "robot2", "tiago"]
    sent = [
        submit(f"move {n} to A", fleet_admin, parse=parse(step([n], *A, "A", speed="fast"))) for n in names
    ]
    done, said_at = wait_each(sim, dict(zip(names, sent, strict=True)), timeout=200)
    assert {name: i.status for name, i in done.items()} == dict.fromkeys(names, "succeeded"), {
        name: i.outcome for name, i in done.items()
    }
    final = {name: sim.pose(name) for name in names}
    for a, b in itertools.combinations(names, 2):
        assert math.dist(final[a][:2], final[b][:2]) > circumscribed(sim, a) + circumscribed(sim, b), (a, b)
    for name, instruction in done.items():  # what each answer says is where the simulator had it then
        words = instruction.executions.get().outcome
        said_matches_pose(words, said_at[name], [n for n in names if n != name])
        assert instruction.outcome.endswith(f"{name}: succeeded ({words})")
    assert sum(i.executions.get().outcome.startswith("arrived at A") for i in done.values()) == 1
