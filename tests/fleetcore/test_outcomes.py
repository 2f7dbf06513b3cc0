"""The one vocabulary of outcomes: what a step did, said from where the robot ended (no database)."""

from fleetcore import outcomes
from fleetcore.steps import Step

A = (2.0, 2.0)


def test_a_robot_within_the_tolerance_of_the_place_arrived_whatever_spot_it_was_given():
    ending = outcomes.judge("A", A, (1.2, 1.2), (2.1, 1.95, 0.0), taken_by="husky")
    assert (ending.kind, ending.words, ending.where) == ("arrived", "arrived at A", "at A")


def test_a_robot_on_the_free_spot_it_was_given_says_so_and_who_took_the_place():
    spot = (1.22, 1.22)
    ending = outcomes.judge("A", A, spot, (1.25, 1.2, 0.0), taken_by="husky")
    assert ending.kind == "free spot" and ending.reached
    assert ending.words == "at a free spot 1.1 m south-west of A; A is taken by husky"
    assert outcomes.judge("A", A, spot, (1.25, 1.2), None).words.endswith("A has no room for it")
    gone = outcomes.judge("A", A, spot, (1.25, 1.2), None, fits=True)  # the one standing there left since
    assert gone.words.endswith("A was taken when it came")


def test_a_robot_anywhere_else_stopped_and_says_where():
    ending = outcomes.judge("A", A, A, (2.0, 2.8, 0.0))
    assert not ending.reached and ending.words == "stopped 0.8 m north of A"
    off_its_spot = outcomes.judge("A", A, (1.22, 1.22), (0.2, 2.0), taken_by="husky")
    assert off_its_spot.words == "stopped 1.8 m west of A"


def test_a_robot_line_reads_as_the_answer_gives_it():
    assert outcomes.robot_line("robot1", "succeeded", "arrived at A") == "robot1: succeeded (arrived at A)"
    assert outcomes.robot_line("robot1", "cancelled", "") == "robot1: cancelled"


def test_a_free_spot_keeps_its_place_and_who_took_it_through_the_step_contract():
    data = {"action": "move", "robots": ["robot2"]}
    data["destination"] = {
        "name": "A",
        "x": 1.2,
        "y": 1.2,
        "around": "A",
        "center": [2, 2],
        "taken_by": "robot1",
    }
    step = Step.from_dict(data)
    assert step.destination.place == ("A", (2.0, 2.0)) and step.destination.taken_by == "robot1"
    assert Step.from_dict(step.to_dict()) == step
    plain = Step.from_dict({"action": "move", "robots": ["r"], "destination": {"name": "B", "x": 1, "y": 2}})
    assert plain.destination.place == ("B", (1.0, 2.0)) and "center" not in plain.to_dict()["destination"]


def test_a_turn_or_move_by_an_amount_is_said_as_its_odometry_measured_it_at_rest():
    assert outcomes.turned(90, 91.4) == "turned 90° left"  # within SAID_AS_ASKED_DEG: as asked
    assert outcomes.turned(90, 104.4) == "turned 104° left (90° left asked)"
    assert outcomes.turned(-45, -44.0) == "turned 45° right"
    assert outcomes.turned(-45, 2.0) == "turned 2° left (45° right asked)"
    assert outcomes.moved(1.0, 1.02) == "moved 1 m forward"
    assert outcomes.moved(-0.5, -0.62) == "moved 0.62 m back (0.5 m back asked)"
    assert outcomes.moved(0.25, 0.1) == "moved 0.1 m forward (0.25 m forward asked)"
