"""Fleet coordination on the simulated demo fleet, judged by what the simulated robots do (ground truth)."""

import itertools
import math
import time

import pytest

from execution.instructions import submit
from execution.models import Instruction
from tests.execution.helpers import parse, step, transitions, wait_each, wait_final

pytestmark = [pytest.mark.slow]

A = (2.0, 2.0)


def displacements(sim, before: dict) -> dict[str, float]:
    """How far each robot has moved from its pose in `before` (the simulator's ground truth)."""
    return {name: math.dist(sim.pose(name)[:2], pose[:2]) for name, pose in before.items()}


@pytest.mark.timeout(150)
def test_move_to_a_and_clean_moves_only_the_nearest_free_capable_robot(
    demo_world, seeded_ontology, fleet_admin
):
    """No robot named: husky goes (4.0 m round the crate to A); turtlebot is 4.7 m away in a straight line
    already, tiago 5.4 m, robot1..4 over 6.5 m. The others stay where they are."""
    sim = demo_world
    before = {name: sim.pose(name) for name in sim.robots}
    instruction = wait_final(submit("Move to A and clean", fleet_admin), timeout=140)
    assert instruction.status == "succeeded", instruction.outcome
    moved = {name: d for name, d in displacements(sim, before).items() if d > 0.3}
    assert list(moved) == ["husky"], moved
    assert math.dist(sim.pose("husky")[:2], A) < 1.0  # cleaned around A
    assert instruction.outcome.startswith(
        "husky chosen (no robot named): the nearest free robot, 4.0 m to A (turtlebot 4.7+ m, tiago 5.4+ m"
    )


def contacts(sim) -> list:
    """Robot-robot contacts the simulator's physics has counted so far."""
    return sim.call(lambda: list(sim.fleet.physics.contacts))


def circumscribed(sim, name) -> float:
    return sim.fleet.robots[name].profile.circumscribed_radius


@pytest.mark.timeout(200)
def test_four_robots_sent_to_a_at_once_end_on_four_spots_without_contact(demo_world, fleet_admin):
    """Four instructions, one per robot, submitted together: A is given once, the others get free spots
    around it (told so), and nobody touches anybody on the way or at the end."""
    sim = demo_world
    names = ["robot1", "robot2", "robot3", "robot4"]
    instructions = [
        submit(f"move {name} to A", fleet_admin, parse=parse(step([name], *A, "A", speed="normal")))
        for name in names
    ]
    ended, said_at = wait_each(sim, dict(zip(names, instructions, strict=True)), timeout=180)
    done = [ended[name] for name in names]
    assert [i.status for i in done] == ["succeeded"] * 4, [i.outcome for i in done]
    assert contacts(sim) == []
    final = {name: sim.pose(name)[:2] for name in names}
    for a, b in itertools.combinations(names, 2):
        assert math.dist(final[a], final[b]) > circumscribed(sim, a) + circumscribed(sim, b), (a, b)
    assert sum("A is taken by" in i.outcome for i in done) == 3
    # the first one stood on A itself when its answer said so (it may since have been asked to make way
    # for one still coming, and stand back beside A: an instruction of its own, in the history)
    assert min(math.dist(pose[:2], A) for pose in said_at.values()) < 0.2


@pytest.mark.timeout(200)
def test_two_pairs_swapping_places_across_each_others_paths_finish_without_contact(demo_world, fleet_admin):
    """turtlebot and husky swap places east-west while tiago and robot4 swap north-south, all at once, their
    straight lines crossing near the middle. Everyone arrives; no two bodies touch."""
    sim = demo_world
    start = {name: sim.pose(name)[:2] for name in ("turtlebot", "husky", "tiago", "robot4")}
    swaps = {
        "turtlebot": start["husky"],
        "husky": start["turtlebot"],
        "tiago": start["robot4"],
        "robot4": start["tiago"],
    }
    goals = {}
    for name, (x, y) in swaps.items():
        goals[name] = submit(
            f"move {name} to {name}'s swap", fleet_admin, parse=parse(step([name], x, y, "S"))
        )
    done = {name: wait_final(instruction, timeout=180) for name, instruction in goals.items()}
    assert {name: i.status for name, i in done.items()} == dict.fromkeys(swaps, "succeeded"), {
        name: i.outcome for name, i in done.items()
    }
    assert contacts(sim) == []
    for name, instruction in done.items():
        destination = instruction.executions.get().steps[0]["destination"]
        off = math.dist(sim.pose(name)[:2], (destination["x"], destination["y"]))
        said = transitions(name)[-1][2]  # the words of its last transition: what it did
        # On arrival a place may be too tight for a big robot (tiago at robot4's start, robot3 parked beside
        # it): it stops at the nearest free spot and says so.
        assert off < 0.25 or ("at a free spot" in said and off < 0.6), (name, off, said)


@pytest.mark.timeout(300)
def test_an_idle_robot_parked_in_a_narrow_way_makes_way_and_comes_back(warehouse_pair, fleet_admin):
    """tb12 parks in the cross aisle's 2 m passage between two shelf racks (x 11.5-12.5), where a Husky
    (1.2 m across) cannot pass it; the way round is 14.5 m against 5.5 m through, longer at a slow pace than
    waiting for tb12 to leave. husky6, sent through slowly, asks tb12 to make way: tb12 moves off its route, waits for it to pass and comes back to its spot. Judged by
    the simulator: both end where they were sent, tb12 was moved aside meanwhile, nobody touched anybody."""
    sim = warehouse_pair
    passage, west, east = (12.0, 12.0), (9.5, 12.0), (15.0, 12.0)
    first = [
        submit("park tb12", fleet_admin, parse=parse(step(["tb12"], *passage, "passage", speed="fast"))),
        submit("husky6 west", fleet_admin, parse=parse(step(["husky6"], *west, "west", speed="normal"))),
    ]
    assert [wait_final(i, timeout=150).status for i in first] == ["succeeded"] * 2, [i.outcome for i in first]
    through = submit("husky6 east", fleet_admin, parse=parse(step(["husky6"], *east, "east", speed="slow")))
    farthest, off_line, deadline = 0.0, 0.0, time.monotonic() + 200
    while not through.is_final and time.monotonic() < deadline:  # watch both while the Husky goes through
        farthest = max(farthest, math.dist(sim.pose("tb12")[:2], passage))
        off_line = max(off_line, abs(sim.pose("husky6")[1] - passage[1]))
        time.sleep(0.2)
        through.refresh_from_db()
    assert through.status == "succeeded", through.outcome
    made_way = Instruction.objects.get(text="tb12 make way for husky6")
    made_way = wait_final(made_way, timeout=120)
    assert made_way.status == "succeeded" and made_way.outcome.startswith(
        "tb12: succeeded (made way for husky6"
    ), made_way.outcome
    assert (made_way.user, made_way.cause) == (None, f"make way for husky6, instruction #{through.pk} by ada")
    assert off_line < 0.5  # the Husky went through the passage, not round the racks
    assert farthest > 1.0  # it moved off the Husky's way (its spot to the passage's side is off the rack)
    assert math.dist(sim.pose("husky6")[:2], east) < 0.3
    assert math.dist(sim.pose("tb12")[:2], passage) < 0.3  # and it came back
    assert contacts(sim) == []
