"""A robot's name is never a grammar word: every keyword of the parser's own phrase table is refused as a name."""

import pytest
from django.core.exceptions import ValidationError

from robots.models import robot_name_from, validate_robot_name

# What the parser reads as the fleet's or the map's data, or drops: no keywords (a robot may be named "Spot").
NOT_KEYWORDS = {"ROBOT", "KIND", "PLACE", "CONCEPT", "CLASSWORD", "FILLER"}


def _keywords(grammar) -> list[str]:
    """Each phrase of the built table that some keyword meaning has, said as a robot name would say it."""
    return sorted(
        "-".join(key)
        for key, meanings in grammar.table.items()
        if {meaning.kind for meaning in meanings} - NOT_KEYWORDS
    )


def test_every_grammar_keyword_is_refused_as_a_robot_name(grammar):
    keywords = _keywords(grammar)
    assert {"from", "between", "inside", "afterwards", "slowly", "stop", "except", "twice"} <= set(keywords)
    allowed = []
    for name in keywords:
        try:
            validate_robot_name(name)
        except ValidationError:
            continue
        allowed.append(name)
    assert allowed == []


def test_registration_never_names_a_robot_after_a_keyword(grammar):
    for name in _keywords(grammar):
        made = robot_name_from(name)
        validate_robot_name(made)  # raises if registration made a name the validator refuses
        assert made != name


@pytest.mark.parametrize("name", ["husky", "Spot", "tb3_0", "robot-and", "fromage", "x1"])
def test_a_name_holding_a_keyword_inside_it_is_still_a_name(name):
    validate_robot_name(name)
