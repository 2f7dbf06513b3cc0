"""Subjects by kind and exclusion (issue 17 item 5, issue 16 item 1), and questions and negations answered at once:
the real interpreter's steps planned by dispatch over robots with poses; no simulator (nothing is run)."""

import pytest

from execution import dispatch, queries
from execution.instructions import submit
from execution.models import Execution
from fleetcore.actions import ACTIONS
from fleetcore.interpretation import Interpretation
from interpreter.service import interpret
from places.worlds import load_world_into_db
from robots.models import Binding, Robot
from robots.poses import forget_poses, store_poses

SQUARE = [[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]]


@pytest.fixture
def fleet(seeded_ontology, exec_settings, monkeypatch):
    """The paper world's places; two TurtleBots and a Husky, ready, with poses; nothing starts running."""
    load_world_into_db("paper")
    monkeypatch.setattr(dispatch.executor, "wake", lambda robot_ids: None)
    made = {}
    for name, model, x, y in (
        ("tb_near", "turtlebot3_burger", 1.0, 1.0),
        ("tb_far", "turtlebot3_burger", -4.0, -4.0),
        ("husky", "husky", 2.0, 1.5),
    ):
        robot = Robot.objects.create(
            name=name, model=model, drive="wheeled", endpoint=f"ws://sim/{name}", footprint=SQUARE,
            link_status="online", state="ready",
        )  # fmt: skip
        for role in ("move", "odometry"):
            Binding.objects.create(robot=robot, action=role, target=f"/{name}/{role}")
        store_poses([{"id": robot.pk, "x": x, "y": y, "yaw": 0.0}])
        made[name] = robot
    yield made
    forget_poses([robot.pk for robot in made.values()])


def planned(text, user) -> set[str]:
    result = interpret(text)
    assert result.valid, result.question
    return {robot.name for robot, _ in dispatch.plan(result, user).items()}


def test_every_robot_except_one(fleet, fleet_admin):
    assert planned("every robot except husky go to C", fleet_admin) == {"tb_near", "tb_far"}
    assert planned("all robots but husky and tb_far go to C", fleet_admin) == {"tb_near"}


def test_a_robot_of_a_model_is_the_nearest_of_that_model(fleet, fleet_admin):
    assert planned("move a turtlebot to A", fleet_admin) == {"tb_near"}  # husky is nearer, not a turtlebot
    assert planned("any husky go to B", fleet_admin) == {"husky"}


def test_the_nearest_free_robot_is_allocated(fleet, fleet_admin):
    assert planned("send the nearest robot to H", fleet_admin) == {"tb_near"}
    fleet["tb_near"].state = "motion"
    fleet["tb_near"].save(update_fields=["state"])
    assert planned("the nearest free robot go to H", fleet_admin) == {"husky"}


def test_a_sequence_for_any_turtlebot_stays_with_the_one_chosen(fleet, fleet_admin):
    result = interpret("a turtlebot go to A, wait 2 seconds, then go to B")
    plan = dispatch.plan(result, fleet_admin)
    [(robot, steps)] = plan.items()
    assert robot.name == "tb_near" and [s["action"] for s in steps] == ["move", "wait", "move"]


def test_no_robot_of_the_model_is_a_refusal_in_words(fleet, fleet_admin):
    with pytest.raises(dispatch.Refused, match="No robot"):
        dispatch.plan(
            Interpretation.direct(
                [{"action": "wait", "robots": {"any": True, "model": "spot"}, "amount": 1}], ""
            ),
            None,
        )


def test_questions_are_answered_at_once_and_nothing_is_queued(fleet, fleet_admin):
    fleet["husky"].state = "motion"
    fleet["husky"].save(update_fields=["state"])
    free = submit("which robots are free", fleet_admin)
    assert free.status == "succeeded"
    assert "Free: tb_far, tb_near." in free.outcome
    assert "husky is busy (motion)" in free.outcome
    where = submit("where is tb_near", fleet_admin)
    assert where.outcome.startswith("tb_near is at (1.00, 1.00)") and "1.0 m from H" in where.outcome
    far = submit("how far is tb_far from Room 3", fleet_admin)
    assert "tb_far is 0.7 m from Room 3 in a straight line" in far.outcome
    can = submit("what can husky do", fleet_admin)
    assert can.outcome.startswith("husky can move, navigate")
    assert not Execution.objects.exists()


def test_a_negated_instruction_moves_nothing_and_says_so(fleet, fleet_admin):
    instruction = submit("don't move husky", fleet_admin)
    assert instruction.status == "succeeded" and "not move husky" in instruction.outcome
    assert not Execution.objects.exists()


def test_every_question_action_has_an_answer():
    asked = {name for name, spec in ACTIONS.items() if spec.category == "query"}
    assert asked == set(queries._ANSWERS)


def test_a_stop_for_every_robot_but_one_names_the_others(fleet):
    from execution.instructions import _stop_names

    assert _stop_names(interpret("stop every robot except husky")) == {"tb_near", "tb_far"}
    assert _stop_names(interpret("stop")) == "all"
