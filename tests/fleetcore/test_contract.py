"""The step contract and the action registry: one vocabulary the interpreter emits and the executor accepts."""

import pytest

from execution.handlers import HANDLERS
from fleetcore import actions, bindings, speed, steps
from fleetcore.choice import ANY, RobotChoice
from fleetcore.speed import SPEEDS, Limits
from fleetcore.states import PRIORITY, State
from fleetcore.steps import Step, StepError


def test_every_speed_word_the_interpreter_knows_the_executor_accepts():
    from fleetcore.grammar import SPEED_PHRASES

    assert set(SPEED_PHRASES) == set(SPEEDS)
    top = speed.Limits(0.5, 1.0)
    paces = [speed.pace(word, top) for word in ("very slow", "slow", "normal", "fast", "very fast")]
    assert [p.limits.linear for p in paces] == sorted(p.limits.linear for p in paces)
    assert paces[-1].limits == top and paces[-1].stack_share is None  # full speed: a stack keeps its own
    assert speed.pace(None, top) == speed.pace("normal", top)


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

    result = interpret(text, grammar).to_dict()
    (step,) = steps.validate(result["steps"])
    assert (step.speed, step.action, step.robots) == (speed, "move", RobotChoice.named("husky"))
    assert 0 < step.pace(Limits(0.5, 1.0)).limits.linear <= 0.5


def test_every_handler_of_the_registry_exists_and_every_role_it_needs_is_a_binding_role():
    for action in actions.ACTIONS.values():
        if action.handler is not None:
            assert callable(HANDLERS[action.handler]), action.name
        for group in action.needs:
            assert set(group) <= set(bindings.ROLES), action.name
    assert set(HANDLERS) == {action.handler for action in actions.ACTIONS.values() if action.handler}


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
        ({"action": "rotate", "robots": ["husky"], "task": "rotate(0)"}, "up to 100"),
        ({"action": "move", "robots": [], "destination": {"x": 1, "y": 2}}, "Say which robot"),
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
    assert step.robots == RobotChoice(ANY) and step.robots.unnamed
    assert Step.from_dict(step.to_dict()) == step


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
