"""The photograph action's words, read by the parser (no Django): a synonym of several words, the robot named
before it or after "with", and a photo as the task done at a destination."""

import pytest

from fleetcore import steps
from interpreter.parser import interpret


@pytest.mark.parametrize(
    "text",
    [
        "tiago, take a photo",
        "take a picture with tiago",
        "tiago take a picture",
        "tiago, snap a photo",
        "capture with tiago",
        "tiago, photograph",
    ],
)
def test_each_phrasing_of_a_photo_is_one_photograph_step_for_tiago(grammar, text):
    result = interpret(text, grammar).to_dict()
    assert result["valid"] and not result["needs_user"], result["reason"]
    assert [(s["action"], s["robots"], s["destination"]) for s in result["steps"]] == [
        ("photograph", ["tiago"], None)
    ]
    (step,) = steps.validate(result["steps"])  # and the executor takes it
    assert step.spec.handler == "photograph" and step.spec.needs == (("camera",),)


def test_a_photo_said_with_a_trip_is_the_task_done_at_the_destination(grammar):
    result = interpret("tiago, go to A and take a photo", grammar).to_dict()
    assert result["valid"], result["reason"]
    (step,) = result["steps"]
    assert (step["action"], step["destination"]["name"], step["task"]) == ("move", "A", "photograph")


def test_a_photo_takes_no_destination_of_its_own(grammar):
    result = interpret("tiago, take a photo at A", grammar).to_dict()
    assert not result["valid"]
    assert "does not take a destination" in result["reason"]
