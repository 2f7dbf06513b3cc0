"""Property tests: no text crashes or hangs the interpreter."""

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetcore.steps import validate
from interpreter.lessons import parse_answer
from interpreter.parser import interpret

WORDS = st.sampled_from(
    ["move", "husky", "to", "A", "then", "and", "clean", "rotate", "5", "times", "(2, -1)", "x", "y", "all",
     "turtlebots", "sea", "roof", "shift", "slowly", ",", ".", "room", "1", "stop", "the", "mvoe", "wait",
     "seconds", "2m", "patrol", "until stopped", "repeat", "except", "a", "forward", "back", "left", "degrees",
     "don't", "twice", "three", "where is", "how far", "from", "any"]
)  # fmt: skip
SHAPE = {
    "type",
    "valid",
    "needs_user",
    "question",
    "steps",
    "read_back",
    "synonyms_used",
    "reason",
    "answer_example",
}
STEP = {"action", "robots", "destination", "task", "speed"}


def check_shape(result: dict) -> None:
    assert set(result) == SHAPE
    assert result["type"] in {"I", "II", "III", "IV", "V"}
    assert result["valid"] == (result["type"] in {"I", "II"}) == (not result["needs_user"])
    assert (result["question"] is None) == result["valid"]
    assert (result["answer_example"] is None) or not result["valid"]
    assert len(result["read_back"]) == len(result["steps"])
    for step in result["steps"]:
        assert STEP <= set(step) <= STEP | {"amount", "span"}
        assert step["robots"] in ("all", "any") or isinstance(step["robots"], list | dict)
    if result["valid"] and result["steps"]:
        validate(result["steps"])  # whatever the interpreter calls understood, the step contract accepts


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.text())
def test_any_unicode_text(grammar, text):
    check_shape(interpret(text, grammar).to_dict())


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(WORDS, max_size=40).map(" ".join))
def test_any_sequence_of_known_words(grammar, text):
    check_shape(interpret(text, grammar).to_dict())


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.text(min_size=1, max_size=300).map(lambda s: (s * (10_000 // len(s) + 1))[:10_000]))
def test_ten_kilobyte_lines(grammar, text):
    check_shape(interpret(text, grammar).to_dict())


@pytest.mark.parametrize(
    "text",
    ["move husky to A " * 700, "(" * 10_000, "x 1 y " * 2000, "9" * 10_000, "\x00\x1b[31m" * 1000,
     "mvoe " * 2000, "a" * 10_000, "Ⅻ ﬁ ① \u200b\u202e move husky to A"],
)  # fmt: skip
def test_pathological_lines(grammar, text):
    check_shape(interpret(text, grammar).to_dict())


@settings(max_examples=200, deadline=None)
@given(st.text())
def test_answers_never_crash(text):
    try:
        parse_answer(text)
    except ValueError as exc:
        assert str(exc)
