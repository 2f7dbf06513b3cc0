"""The plain parser against the paper's fleet, without Django."""

import pytest

from interpreter.parser import interpret

from .acceptance import rows, summary


@pytest.mark.parametrize("row", rows(), ids=lambda r: r["text"])
def test_acceptance_row(grammar, row):
    expected = {k: v for k, v in row.items() if k != "text"}
    assert summary(interpret(row["text"], grammar).to_dict()) == expected


def run(grammar, text):
    return interpret(text, grammar).to_dict()


@pytest.mark.parametrize(
    ("text", "kind", "action", "robots", "dest"),
    [
        ("move the husky to B", "I", "move", ["husky"], "B"),
        ("please, move husky to b.", "I", "move", ["husky"], "B"),
        ("Robot husky: move to room 2", "I", "move", ["husky"], "Room 2"),
        ("move robot 3 to room2", "I", "move", ["robot3"], "Room 2"),
        ("navigate tb3_nav2 to F", "I", "navigate", ["tb3_nav2"], "F"),
        ("head to E", "II", "move", "any", "E"),
        ("husky and tiago, drive to D", "II", "move", ["husky", "tiago"], "D"),
        ("travel to the A", "II", "move", "any", "A"),
        ("Make your way to H", "II", "move", "any", "H"),
        ("proceed to I", "II", "move", "any", "I"),
        ("go to A", "II", "move", "any", "A"),
        ("move all robots to A", "I", "move", "all", "A"),
        ("move everyone to C", "I", "move", "all", "C"),
    ],
)
def test_plain_and_synonym_phrasings(grammar, text, kind, action, robots, dest):
    result = run(grammar, text)
    step = result["steps"][0]
    assert (result["type"], step["action"], step["robots"], step["destination"]["name"]) == (
        kind,
        action,
        robots,
        dest,
    )
    assert result["valid"] and not result["needs_user"] and result["question"] is None


@pytest.mark.parametrize(
    ("text", "word", "canonical"),
    [
        ("mvoe husky to A", "mvoe", "move"),
        ("move husy to A", "husy", "husky"),
        ("navgiate tiago to H", "navgiate", "navigate"),
    ],
)
def test_small_typos_are_read_as_the_known_word(grammar, text, word, canonical):
    result = run(grammar, text)
    assert result["valid"], result
    assert f"'{word}' as '{canonical}'" in result["reason"]


@pytest.mark.parametrize(
    "text",
    ["move husky to sea", "move husky to see", "move husky to the mars base", "step husky to A",
     "more husky to A", "move robot9 to A", "move husky to room 7", "move husky to A quietly",
     "clear room 1", "move husky to the kitchen"],
)  # fmt: skip
def test_unknown_words_are_never_silently_accepted(grammar, text):
    result = run(grammar, text)
    assert result["type"] == "V" and result["needs_user"] and result["question"], result


def test_sea_is_not_read_as_c_or_see(grammar):
    result = run(grammar, "Proceed to sea and clean")
    assert result["steps"][0]["destination"] == {"name": "sea", "x": None, "y": None}
    assert "sea is not a place" in result["question"]


def test_kinds_expand_to_the_robots_of_that_model(grammar):
    step = run(grammar, "move all turtlebots to A")["steps"][0]
    assert step["robots"] == ["turtlebot", "robot1", "robot2", "robot3", "robot4", "tb3_nav2"]
    assert run(grammar, "stop all legged robots")["steps"][0]["robots"] == ["spot"]
    assert run(grammar, "move the huskies to B")["steps"][0]["robots"] == ["husky"]


@pytest.mark.parametrize(
    ("text", "x", "y"),
    [("move husky to (2, -1)", 2.0, -1.0), ("move husky to x 2 y -1", 2.0, -1.0), ("go to [0.5 3]", 0.5, 3.0),
     ("move to x=-3.5, y=4", -3.5, 4.0)],
)  # fmt: skip
def test_coordinates(grammar, text, x, y):
    dest = run(grammar, text)["steps"][0]["destination"]
    assert (dest["x"], dest["y"]) == (x, y)


@pytest.mark.parametrize(
    ("text", "task"),
    [("move husky to A and rotate 5 times", "rotate(5)"), ("move to B and rotate(3)", "rotate(3)"),
     ("rotate tiago twice", "rotate(2)"), ("move to C, then clean", "clean"), ("spin husky", "rotate(1)")],
)  # fmt: skip
def test_tasks(grammar, text, task):
    steps = run(grammar, text)["steps"]
    assert task in [s["task"] for s in steps]


@pytest.mark.parametrize(
    ("text", "speed"),
    [("move husky slowly to A", "slow"), ("move husky to A fast", "fast"), ("move husky very fast to A", "very fast"),
     ("quickly go to A", "fast"), ("move husky to A", None)],
)  # fmt: skip
def test_speed_words(grammar, text, speed):
    assert run(grammar, text)["steps"][0]["speed"] == speed


def test_several_steps_inherit_action_and_robots(grammar):
    steps = run(grammar, "move husky to D and then E, then rotate 2 times")["steps"]
    assert [s["action"] for s in steps] == ["move", "move", "rotate"]
    assert [s["destination"]["name"] if s["destination"] else None for s in steps] == ["D", "E", None]
    assert all(s["robots"] == ["husky"] for s in steps)
    both = run(grammar, "move husky to A and tiago to B")["steps"]
    assert [(s["robots"], s["destination"]["name"]) for s in both] == [(["husky"], "A"), (["tiago"], "B")]


@pytest.mark.parametrize(
    ("text", "kind"),
    [("move husky", "III"), ("shift husky", "IV"), ("stop husky at A", "III"), ("move to the room", "III"),
     ("walk husky to the ceiling", "IV"), ("move to the moon", "III")],
)  # fmt: skip
def test_semantic_issues_ask_the_user(grammar, text, kind):
    result = run(grammar, text)
    assert result["type"] == kind and result["needs_user"] and result["question"]


def test_type_v_questions_say_what_to_answer(grammar):
    question = run(grammar, "flurble to A")["question"]
    assert "flurble means move" in question


@pytest.mark.parametrize("text", ["", "   ", "!!!", "\x00\x01", "please"])
def test_empty_or_meaningless_input_is_a_clear_question(grammar, text):
    result = run(grammar, text)
    assert result["type"] == "V" and result["question"]


def test_a_and_i_are_only_places_after_a_preposition(grammar):
    assert run(grammar, "move a robot to B")["steps"][0]["destination"]["name"] == "B"
    assert run(grammar, "move husky to a")["steps"][0]["destination"]["name"] == "A"
    assert run(grammar, "move husky to i")["steps"][0]["destination"]["name"] == "I"


@pytest.mark.parametrize("name", ["tb3_nav2", "turtlebot3_burger_2", "robot-7", "spot2", "UGV_01-b"])
def test_every_registered_name_is_understood(name):
    """Names with digits, dashes and underscores are robots, as registration writes them."""
    from interpreter.lexicon import Fleet, Grammar, Lexicon, RobotInfo
    from interpreter.terms import seed_terms
    from tests.interpreter.conftest import paper_fleet

    fleet = paper_fleet()
    grammar = Grammar(
        Lexicon(seed_terms()), Fleet([*fleet.robots, RobotInfo(name, "husky", "wheeled")], fleet.places)
    )
    result = interpret(f"move {name} to A", grammar).to_dict()
    assert result["type"] == "I", result["question"]
    assert result["steps"][0]["robots"] == [name]


@pytest.mark.parametrize("text", ["husky, make way", "tiago make room", "turtlebot get out of the way"])
def test_make_way_is_an_instruction_to_the_robot_named(grammar, text):
    result = run(grammar, text)
    assert result["valid"] and not result["needs_user"], result
    assert [(s["action"], s["robots"]) for s in result["steps"]] == [
        ("make_way", [text.split()[0].strip(",")])
    ]


def test_make_way_said_to_nobody_is_said_to_every_robot(grammar):
    assert run(grammar, "make way")["steps"][0]["robots"] == "all"


def test_make_your_way_is_still_a_move(grammar):
    assert run(grammar, "husky make your way to B")["steps"][0]["action"] == "move"
