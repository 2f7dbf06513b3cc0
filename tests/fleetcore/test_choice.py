"""Which robots an instruction means: one plain function for every form a step names robots in."""

import pytest

from fleetcore.choice import RobotChoice, kind_words, means, unnamed

FLEET = [("husky", "husky", "wheeled"), ("tb1", "turtlebot3_burger", "wheeled"), ("spot", "spot", "legged")]


def _meant(robots) -> list[str]:
    return [name for name, model, drive in FLEET if means(robots, name, model, drive)]


@pytest.mark.parametrize(
    ("robots", "names"),
    [
        (["tb1", "spot"], ["tb1", "spot"]),
        ("all", ["husky", "tb1", "spot"]),
        ("any", ["husky", "tb1", "spot"]),
        (None, ["husky", "tb1", "spot"]),
        ({"all": True, "except": ["husky"]}, ["tb1", "spot"]),
        ({"any": True, "model": "turtlebot"}, ["tb1"]),
        ({"all": True, "model": "legged"}, ["spot"]),
        (RobotChoice("all", (), "wheeled", ("tb1",)), ["husky"]),
    ],
)
def test_the_robots_a_step_means(robots, names):
    assert _meant(robots) == names


@pytest.mark.parametrize(
    ("robots", "left_to_the_portal"),
    [("any", True), (None, True), ("", True), ({"any": True, "model": "husky"}, True), (RobotChoice("any"), True),
     ("all", False), (["husky"], False), ({"all": True, "except": ["tb1"]}, False)],
)  # fmt: skip
def test_unnamed_leaves_the_choice_to_the_portal(robots, left_to_the_portal):
    assert unnamed(robots) is left_to_the_portal


def test_kind_words_of_a_model():
    assert {"turtlebot3", "turtlebot", "burger", "wheeled"} <= kind_words("turtlebot3_burger", "wheeled")
