"""A step's speed: one function from the word and a robot's limits to everything driven at it (fleetcore.speed)."""

import pytest

from fleetcore import speed
from fleetcore import traffic_tuning as tune
from fleetcore.speed import SPEEDS, Limits, UnknownSpeed, pace
from fleetcore.steps import Step, StepError

TIAGO = Limits(1.0, 1.0)


@pytest.mark.parametrize("word", [*SPEEDS, None, "", " Slow "])
def test_a_word_asks_each_robot_for_its_share_of_its_own_limits(word):
    asked = pace(word, TIAGO)
    share = SPEEDS[speed.word(word)]
    assert asked.limits == Limits(TIAGO.linear * share, TIAGO.angular * share)
    assert asked.planned(nav=False) == pytest.approx(asked.limits.linear * tune.PLANNED_SPEED)


def test_slower_words_are_slower_everywhere_the_speed_is_read():
    slow, normal, top = pace("slow", TIAGO), pace(None, TIAGO), pace("very fast", TIAGO)
    assert slow.limits.linear < normal.limits.linear < top.limits.linear == TIAGO.linear
    assert slow.stack_share < normal.stack_share and top.stack_share is None  # top: the stack's own speed
    assert slow.stack_limits.linear < normal.stack_limits.linear  # a nav stack's stretch given more time
    assert normal.stack_limits.linear <= tune.NAV_TOP_MPS * tune.NAV_PACE_GUESS
    assert slow.planned(nav=False) < normal.planned(nav=False)


def test_a_nav_stack_is_planned_at_the_pace_it_was_seen_to_drive():
    assert pace("slow", TIAGO).planned(nav=True, learned=0.3) == pytest.approx(0.3 * tune.PLANNED_SPEED)
    assert pace("slow", TIAGO).planned(nav=True) == pytest.approx(TIAGO.linear * tune.PLANNED_SPEED)


def test_an_unknown_word_is_refused_with_the_words_there_are():
    with pytest.raises(UnknownSpeed, match=r"warp.*very slow, slow, normal, fast, very fast"):
        pace("warp", TIAGO)
    with pytest.raises(StepError, match="unknown speed 'warp'"):
        Step.from_dict({"action": "move", "destination": {"name": "A", "x": 1, "y": 2}, "speed": "warp"})


def test_a_step_reads_its_pace_through_the_one_function():
    step = Step.from_dict({"action": "move", "destination": {"name": "A", "x": 1, "y": 2}, "speed": "slow"})
    assert step.pace(TIAGO) == pace("slow", TIAGO)
