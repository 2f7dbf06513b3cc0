"""Dialogue (issue 17 item 8): answers are judged against the word the question asked about."""

import pytest

from execution.models import Instruction
from interpreter.models import Lesson
from interpreter.service import interpret, teach

pytestmark = pytest.mark.django_db


def asked(text: str) -> Instruction:
    return Instruction.objects.create(text=text, status="needs_user")


def test_a_bad_answer_gets_an_example_about_the_word_asked(paper_world, operator):
    result = teach("fly like the wind", operator, asked("zoom tiago to B"))
    assert not result["ok"]
    assert result["examples"][0] == "zoom means move"
    assert result["message"].count("Try e.g.") == 1 and result["message"].endswith(
        "Try e.g. 'zoom means move'."
    )


def test_a_bare_word_answers_the_question_about_a_word(paper_world, operator):
    result = teach("move", operator, asked("zoom tiago to B"))
    assert result["ok"] and (result["word"], result["meaning"]) == ("zoom", "move")
    assert interpret("zoom tiago to B").to_dict()["valid"]
    assert Lesson.objects.get().word == "zoom"


def test_a_bare_word_the_interpreter_does_not_know_either_is_refused_with_an_example(paper_world, operator):
    result = teach("fly", operator, asked("zoom tiago to B"))
    assert not result["ok"] and "'fly'" in result["message"] and "zoom means move" in result["message"]
    assert not Lesson.objects.exists()


def test_a_place_question_gets_place_examples(paper_world, operator):
    result = teach("what?", operator, asked("move husky to the sea"))
    assert not result["ok"] and result["examples"][:2] == ["sea means A", "sea is a location at (3, 4)"]
