"""The forms people type (issue 17): what the interpreter makes of them, step by step (no database)."""

import pytest

from fleetcore.actions import ACTIONS
from fleetcore.steps import validate
from interpreter.parser import interpret


def run(grammar, text):
    result = interpret(text, grammar).to_dict()
    if result["valid"]:
        validate(result["steps"]) if result["steps"] else None  # the executor's contract accepts them
    return result


def steps(grammar, text):
    result = run(grammar, text)
    assert result["valid"], result["question"]
    return [(s["action"], s.get("amount"), (s["destination"] or {}).get("name")) for s in result["steps"]]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("move husky 2 meters forward", [("move_by", 2.0, None)]),
        ("move husky 2m forward", [("move_by", 2.0, None)]),
        ("husky, go back 150 cm", [("move_by", -1.5, None)]),
        ("drive tiago backwards half a meter", [("move_by", -0.5, None)]),
        ("move robot1 forward by two metres", [("move_by", 2.0, None)]),
        ("turn tiago left", [("turn_by", 90.0, None)]),
        ("turn tiago right", [("turn_by", -90.0, None)]),
        ("turn husky by 45 degrees", [("turn_by", 45.0, None)]),
        ("turn husky clockwise by forty five degrees", [("turn_by", -45.0, None)]),
        ("rotate 180 degrees", [("turn_by", 180.0, None)]),
        ("rotate husky one hundred eighty degrees", [("turn_by", 180.0, None)]),
        ("spin around", [("rotate", None, None)]),
        ("turn husky around", [("turn_by", 180.0, None)]),
        ("wait 5 seconds", [("wait", 5.0, None)]),
        ("wait a minute", [("wait", 60.0, None)]),
    ],
)
def test_relative_motion_turns_and_waits_carry_their_amount(grammar, text, expected):
    assert steps(grammar, text) == expected


@pytest.mark.parametrize(
    "text",
    [
        "go to B, wait 5 seconds, then go to C",
        "go to B and then wait 5 seconds and then go to C",
        "first go to B, after that wait five seconds, then go to C",
        "go to B. Wait 5 s. Go to C",
    ],
)
def test_sequences_with_a_wait(grammar, text):
    assert steps(grammar, text) == [("move", None, "B"), ("wait", 5.0, None), ("move", None, "C")]


def test_robots_carry_through_a_sequence(grammar):
    result = run(grammar, "move husky to A, wait 5 seconds, then go to B")
    assert [s["robots"] for s in result["steps"]] == [["husky"]] * 3


def test_number_words_name_a_numbered_place(grammar):
    assert steps(grammar, "tiago go to room three") == [("move", None, "Room 3")]


@pytest.mark.parametrize(
    "text",
    [
        "husky, come back to your start",
        "go back to where you started",
        "return to your start",
        "go home",
        "dock",
    ],
)
def test_return_is_the_dock_action(grammar, text):
    assert [s["action"] for s in run(grammar, text)["steps"]] == ["dock"]


def test_patrol_with_rounds_is_written_out(grammar):
    assert [d for _, _, d in steps(grammar, "patrol between A and B twice")] == ["A", "B", "A", "B"]
    assert [d for _, _, d in steps(grammar, "patrol A and B 3 times")] == ["A", "B"] * 3


def test_patrol_until_stopped_ends_in_a_repeat_of_its_visits(grammar):
    result = run(grammar, "patrol A, B and C until stopped")
    assert [s["action"] for s in result["steps"]] == ["move", "move", "move", "repeat"]
    assert result["steps"][-1]["span"] == 3 and "amount" not in result["steps"][-1]


def test_patrol_without_rounds_goes_on_until_stopped_with_the_robot_named_at_the_end(grammar):
    result = run(grammar, "patrol A and B with tiago")
    assert [s["robots"] for s in result["steps"]] == [["tiago"]] * 3
    assert result["steps"][-1] == {**result["steps"][-1], "action": "repeat", "span": 2}


def test_repeat_does_the_steps_before_it_again(grammar):
    assert [d for _, _, d in steps(grammar, "go to A then B, repeat 3 times")] == ["A", "B"] * 3
    forever = run(grammar, "go to A then B, then repeat until stopped")["steps"]
    assert [s["action"] for s in forever] == ["move", "move", "repeat"] and forever[-1]["span"] == 2
    assert run(grammar, "repeat 3 times")["question"].startswith("Repeat what?")


def test_too_many_rounds_are_asked_about(grammar):
    result = run(grammar, "patrol A, B, C and D 60 times")
    assert result["needs_user"] and "more than 200 steps" in result["question"]


@pytest.mark.parametrize(
    ("text", "robots"),
    [
        ("every robot except husky go to C", {"all": True, "except": ["husky"]}),
        ("all robots but husky and tiago go to D", {"all": True, "except": ["husky", "tiago"]}),
        ("move a turtlebot to A", {"any": True, "model": "turtlebot"}),
        ("any turtlebot go to B", {"any": True, "model": "turtlebot"}),
        ("send the nearest robot to D", "any"),
        ("the nearest free robot go to E", "any"),
        ("any robot go to B", "any"),
        ("move robot1 and robot2 to A", ["robot1", "robot2"]),
        ("move tb3_nav2 to A", ["tb3_nav2"]),
        ("move all turtlebots to A", ["turtlebot", "robot1", "robot2", "robot3", "robot4", "tb3_nav2"]),
    ],
)
def test_subjects(grammar, text, robots):
    result = run(grammar, text)
    assert result["valid"], result["question"]
    assert result["steps"][0]["robots"] == robots


def test_do_not_drops_the_task(grammar):
    result = run(grammar, "move to A and do not clean")
    assert result["valid"] and result["steps"][0]["task"] is None
    assert "not clean" in result["reason"]


def test_do_not_move_is_understood_as_nothing_to_do(grammar):
    result = run(grammar, "don't move tiago")
    assert result["valid"] and result["steps"] == [] and "Nothing to do: not move tiago" in result["reason"]


def test_a_not_that_fits_no_action_is_asked_about(grammar):
    result = run(grammar, "move husky to A not B")
    assert result["needs_user"] and "'not'" in result["question"]


@pytest.mark.parametrize(
    ("text", "action", "robots"),
    [
        ("where is tiago", "report_position", ["tiago"]),
        ("what is husky doing", "report_status", ["husky"]),
        ("which robots are free", "list_free", "all"),
        ("how far is husky from A", "report_distance", ["husky"]),
        ("what can turtlebot do", "list_abilities", ["turtlebot"]),
    ],
)
def test_questions_are_query_steps(grammar, text, action, robots):
    step = run(grammar, text)["steps"][0]
    assert (step["action"], step["robots"]) == (action, robots)
    assert ACTIONS[action].category == "query"


@pytest.mark.parametrize(
    ("text", "example"),
    [
        ("zoom tiago to B", "zoom means move"),
        ("move husky to sea", "sea means A"),
        ("move husky forward", "move husky 1 meter forward"),
        ("wait", "wait 5 seconds"),
        ("move husky", "move husky to A"),
        ("move husky to Roon 3", "roon 3 means Room 3"),
    ],
)
def test_each_question_comes_with_an_answer_example_that_fits_it(grammar, text, example):
    result = run(grammar, text)
    assert result["needs_user"] and result["answer_example"] == example, result["question"]


def test_did_you_mean_for_near_miss_robots_and_places(grammar):
    assert "Did you mean husky?" in run(grammar, "move huskyy to A")["question"]
    assert "Did you mean Room 3?" in run(grammar, "move husky to Roon 3")["question"]
    assert "Did you mean robot1?" in run(grammar, "move robot11 to A")["question"]


def test_an_unknown_verb_is_asked_about_with_the_verbs_a_person_types(grammar):
    question = run(grammar, "zoom husky to A")["question"]
    known = question.split("I know: ", 1)[1].rstrip(").").split(", ")
    assert {"move", "rotate", "dock", "patrol", "wait", "stop"} <= set(known)
    assert not [verb for verb in known if "_" in verb]  # not move_by, report_status, list_free...


@pytest.mark.parametrize(
    ("text", "task", "read_back"),
    [
        ("rotate tiago 3 times", "rotate(3)", "rotate tiago 3 times"),
        ("spin tiago twice", "rotate(2)", "rotate tiago 2 times"),
        ("rotate tiago", "rotate(1)", "rotate tiago"),
    ],
)
def test_a_task_said_n_times_is_one_step_read_back_with_its_count(grammar, text, task, read_back):
    """Issue 31: "rotate tiago 3 times" is one rotate step done three times, said so (not "then rotate(3)")."""
    result = run(grammar, text)
    assert [(s["action"], s["robots"], s["task"]) for s in result["steps"]] == [("rotate", ["tiago"], task)]
    assert result["read_back"] == [read_back]
    assert f"Understood: {read_back}." in result["reason"]


def test_a_task_after_a_move_is_read_back_as_what_follows_it(grammar):
    result = run(grammar, "husky go to B and spin twice")
    assert [(s["action"], s["task"]) for s in result["steps"]] == [("move", "rotate(2)")]
    assert result["read_back"] == ["move husky to B, then rotate 2 times"]
    assert run(grammar, "go to A")["read_back"] == ["move a robot the portal chooses to A"]
