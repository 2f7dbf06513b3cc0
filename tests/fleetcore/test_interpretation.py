"""The one typed interpretation: its JSON edges, and "is it a stop", "which robots" decided on it once."""

from dataclasses import fields

import pytest

from fleetcore.choice import ChoiceError, RobotChoice, SubjectWire
from fleetcore.interpretation import EVERY, Interpretation
from fleetcore.steps import Destination, DestinationWire, StepWire

FLEET = [("husky", "husky", "wheeled"), ("tb1", "turtlebot3_burger", "wheeled"), ("spot", "spot", "legged")]


def _said(text, grammar) -> Interpretation:
    from interpreter.parser import interpret

    return interpret(text, grammar)


@pytest.mark.parametrize(
    "text",
    [
        "move husky slowly to A",
        "every robot except husky go to C",
        "stop",
        "go to A then B",
        "zoom husky to A",
    ],
)
def test_the_stored_json_comes_back_as_the_same_interpretation(grammar, text):
    understood = _said(text, grammar)
    stored = understood.to_dict()
    assert set(stored) == {"type", "valid", "needs_user", "question", "steps", "read_back", "synonyms_used",
                           "reason", "answer_example"}  # fmt: skip
    assert Interpretation.from_dict(stored) == understood
    assert Interpretation.from_dict(stored).to_dict() == stored


def test_the_wire_forms_declared_once_hold_every_key_written(grammar):
    """The API's schema is generated from these declarations (portal/interpretation_schema.py): the parser's
    steps, the checked steps and the robots' subject objects write no key they do not declare."""
    texts = ["move husky slowly to A", "every robot except husky go to C", "any turtlebot go to B",
             "move husky forward 2 metres", "patrol A, B and C until stopped", "cancel #12", "zoom husky to A"]  # fmt: skip
    written = set()
    for text in texts:
        understood = _said(text, grammar)
        assert set(understood.to_dict()) == set(Interpretation.wire_form()), text
        for step in understood.steps:
            assert StepWire.__required_keys__ <= set(step), text
            written |= set(step) | (set(step["robots"]) if isinstance(step["robots"], dict) else set())
        if understood.valid and not understood.cancels:
            written |= {key for checked in understood.checked() for key in checked.to_dict()}
    declared = set(StepWire.__annotations__) | set(SubjectWire.__annotations__)
    assert written == declared  # each key declared is written by some step, and no other
    assert {f.name for f in fields(Destination)} == set(DestinationWire.__annotations__)


def test_a_stop_is_decided_once_and_names_its_robots(grammar):
    def fleet():
        return FLEET

    assert _said("stop", grammar).is_stop and _said("stop", grammar).stop_names(fleet) == EVERY
    assert _said("halt everything", grammar).stop_names(fleet) == EVERY
    assert _said("stop husky", grammar).stop_names(fleet) == {"husky"}
    assert _said("stop every robot except husky", grammar).stop_names(fleet) == {"tb1", "spot"}
    assert not _said("move husky to A", grammar).is_stop


def test_the_fleet_is_read_only_for_a_choice_by_kind_or_exclusion(grammar):
    def no_fleet():
        raise AssertionError("the fleet was read")

    assert _said("stop husky", grammar).stop_names(no_fleet) == {"husky"}


def test_an_instruction_the_portal_writes_is_one_constructor():
    made = Interpretation.for_robots(["husky"], "move", "schedule", {"name": "A", "x": 1.0, "y": 2.0})
    assert (made.type, made.valid, made.needs_user, made.choices) == (
        "I",
        True,
        False,
        (RobotChoice.named("husky"),),
    )
    (step,) = made.checked()
    assert step.robots.names == ("husky",) and step.destination.name == "A"


def test_a_hand_written_dict_converts():
    """The shape make-way (execution/traffic.py) still writes: no reason, no question."""
    made = Interpretation.from_dict(
        {
            "type": "I",
            "valid": True,
            "needs_user": False,
            "steps": [{"action": "make_way", "robots": ["tb1"]}],
        }
    )
    assert made.valid and made.choices == (RobotChoice.named("tb1"),) and not made.is_stop
    assert Interpretation.from_dict({"type": "I", "needs_user": True, "steps": []}).needs_user


def test_questions_and_releases_are_properties():
    where = Interpretation.direct([{"action": "report_position", "robots": ["husky"]}], "")
    assert where.is_question and not where.releases
    assert Interpretation.direct([{"action": "release", "robots": "all"}], "").releases


@pytest.mark.parametrize(
    ("wire", "choice"),
    [
        (["husky"], RobotChoice("names", ("husky",))),
        ("all", RobotChoice("all")),
        (None, RobotChoice("any")),
        ({"any": True, "model": "turtlebot"}, RobotChoice("any", (), "turtlebot")),
        ({"all": True, "except": ["husky"]}, RobotChoice("all", (), None, ("husky",))),
    ],
)
def test_every_form_of_robots_is_one_type(wire, choice):
    assert RobotChoice.of(wire) == choice
    assert RobotChoice.of(choice.to_wire()) == choice


@pytest.mark.parametrize("wire", [[], 5, {"all": True, "any": True}, {"all": True, "colour": "red"}])
def test_robots_in_no_form_are_refused_in_words(wire):
    with pytest.raises(ChoiceError):
        RobotChoice.of(wire)
