"""The step contract and the action registry: one vocabulary the interpreter emits and the executor accepts."""

import pytest
from django.utils.module_loading import import_string

from fleetcore import actions, bindings, steps
from fleetcore.states import PRIORITY, State
from fleetcore.steps import SPEEDS, Step, StepError


def test_every_speed_word_the_interpreter_knows_the_executor_accepts():
    from interpreter.lexicon import _SPEED_PHRASES

    assert set(_SPEED_PHRASES) == set(SPEEDS)
    factors = [steps.speed_factor(word) for word in ("very slow", "slow", "normal", "fast", "very fast")]
    assert factors == sorted(factors) and factors[-1] == 1.0 and steps.speed_factor(None) == SPEEDS["normal"]


@pytest.mark.parametrize(
    ("text", "speed"),
    [
        ("move husky very slowly to A", "very slow"),
        ("move husky slowly to A", "slow"),
        ("move husky at normal speed to A", "normal"),
        ("move husky fast to A", "fast"),
        ("move husky very fast to A", "very fast"),
    ],
)
def test_each_spoken_speed_parses_to_a_step_the_executor_takes(grammar, text, speed):
    from interpreter.parser import interpret

    result = interpret(text, grammar).as_dict()
    (step,) = steps.validate(result["steps"])
    assert (step.speed, step.action, step.robots) == (speed, "move", ("husky",))
    assert 0 < step.factor <= 1


def test_every_handler_of_the_registry_exists_and_every_role_it_needs_is_a_binding_role():
    for action in actions.ACTIONS.values():
        if action.handler is not None:
            assert callable(import_string(action.handler)), action.name
        for group in action.needs:
            assert set(group) <= set(bindings.ROLES), action.name


def test_dock_is_motion_priority_and_a_query_never_outranks_motion():
    assert actions.get("dock").priority == PRIORITY[State.MOTION]
    assert actions.get("report_position").priority < actions.get("move").priority
    assert Step.from_dict({"task": "rotate(2)", "robots": ["tiago"]}).priority == PRIORITY[State.WORK]


@pytest.mark.parametrize(
    ("step", "error"),
    [
        ({"action": "fly", "robots": ["husky"]}, "unknown action 'fly'"),
        ({"action": "move", "robots": ["husky"]}, "say where to move"),
        ({"action": "move", "robots": ["husky"], "destination": {"name": "A"}}, "has no position"),
        ({"action": "move", "robots": ["husky"], "destination": {"x": "nan", "y": 0}}, "finite"),
        ({"action": "move", "robots": ["husky"], "destination": {"x": 1, "y": 2}, "speed": "warp"}, "warp"),
        ({"action": "rotate", "robots": ["husky"], "task": "rotate(0)"}, "1 to 100"),
        ({"action": "clean", "robots": ["husky"], "task": "clean(3)"}, "unknown task"),
        ({"action": "move", "robots": 5, "destination": {"x": 1, "y": 2}}, "robots is a list"),
        ("move", "a step is an object"),
    ],
)
def test_a_step_the_executor_cannot_run_is_refused_with_a_reason(step, error):
    with pytest.raises(StepError, match=error):
        Step.from_dict(step)


def test_a_step_round_trips_and_names_no_robot_as_any():
    step = Step.from_dict({"action": "move", "destination": {"name": "A", "x": 1, "y": 2}, "speed": "fast"})
    assert step.robots == steps.ANY
    assert Step.from_dict(step.to_dict()) == step
    assert step.for_robot("husky").robots == ("husky",)


def test_the_seed_ontology_comes_from_the_registries():
    from interpreter.terms import SEED_ACTIONS, SEED_KEYWORDS, SEED_SYNONYMS

    assert {a.name for a in SEED_ACTIONS} == set(actions.ACTIONS)
    assert {s.word for s in SEED_SYNONYMS if s.action == "dock"} == set(actions.get("dock").synonyms)
    assert {(k.action, k.keyword) for k in SEED_KEYWORDS} == {
        (role.name, word) for role in bindings.ROLES.values() for word in role.keywords
    }


def test_binding_types_are_checked_in_either_ros_spelling():
    assert bindings.accepts("move", "geometry_msgs/msg/Twist")
    assert bindings.accepts("odometry", "nav_msgs/Odometry")
    assert not bindings.accepts("move", "nav_msgs/Odometry")
    assert bindings.accepts("dock", "irobot_create_msgs/action/Dock")
