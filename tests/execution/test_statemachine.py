"""The per-robot state machine of the paper's Figures 5 and 6, as a table."""

import pytest

from fleetcore.states import (
    PRIORITY,
    Admission,
    Event,
    IllegalTransition,
    State,
    admit,
    can,
    next_state,
)
from fleetcore.steps import priority


def test_the_paper_cycle_registered_ready_dialog_motion_work_ready():
    state = State.REGISTERED
    for event, expected in [
        (Event.LINK_UP, State.READY),
        (Event.ASK, State.DIALOG),
        (Event.MOVE, State.MOTION),
        (Event.WORK, State.WORK),
        (Event.DONE, State.READY),
    ]:
        state = next_state(state, event)
        assert state == expected


@pytest.mark.parametrize("state", [State.READY, State.DIALOG, State.MOTION, State.WORK, State.REGISTERED])
def test_link_down_makes_any_state_offline(state):
    assert next_state(state, Event.LINK_DOWN) == State.OFFLINE


def test_idle_timeout_only_from_ready():
    assert next_state(State.READY, Event.IDLE_TIMEOUT) == State.OFFLINE
    assert not can(State.MOTION, Event.IDLE_TIMEOUT)
    assert not can(State.WORK, Event.IDLE_TIMEOUT)


def test_offline_robot_comes_back_only_through_link_up():
    assert next_state(State.OFFLINE, Event.LINK_UP) == State.READY
    for event in (Event.MOVE, Event.WORK, Event.ASK, Event.DONE):
        assert not can(State.OFFLINE, event)


def test_illegal_transition_names_state_and_event():
    with pytest.raises(IllegalTransition, match=r"'ready'.*'done'"):
        next_state(State.READY, Event.DONE)
    with pytest.raises(IllegalTransition):
        next_state("flying", Event.DONE)
    with pytest.raises(IllegalTransition):
        next_state(State.READY, "teleport")


def test_priorities_work_over_motion_over_dialog_over_ready():
    assert PRIORITY[State.WORK] > PRIORITY[State.MOTION] > PRIORITY[State.DIALOG] > PRIORITY[State.READY]


def test_step_priorities_come_from_the_action_registry():
    assert priority([{"destination": {"x": 1, "y": 2}}]) == PRIORITY[State.MOTION]
    assert priority([{"destination": None, "task": "rotate(5)"}]) == PRIORITY[State.WORK]
    assert priority([{"destination": {"x": 1, "y": 2}}, {"task": "clean"}]) == PRIORITY[State.WORK]
    assert priority([]) == PRIORITY[State.READY]


def test_dock_moves_the_robot_so_it_runs_at_motion_priority_not_dialog():
    assert priority([{"action": "dock", "robots": ["husky"]}]) == PRIORITY[State.MOTION]


@pytest.mark.parametrize(
    ("state", "priority", "expected"),
    [
        (State.READY, PRIORITY[State.MOTION], Admission.START),
        (State.MOTION, PRIORITY[State.WORK], Admission.PREEMPT),  # a work instruction preempts a motion
        (State.MOTION, PRIORITY[State.MOTION], Admission.QUEUE),  # equal priority waits
        (State.WORK, PRIORITY[State.MOTION], Admission.QUEUE),
        (State.WORK, PRIORITY[State.WORK], Admission.QUEUE),
        (State.DIALOG, PRIORITY[State.MOTION], Admission.PREEMPT),
        (State.OFFLINE, PRIORITY[State.WORK], Admission.REFUSE),
    ],
)
def test_admission_preempts_only_lower_priority(state, priority, expected):
    assert admit(state, priority) == expected


def test_next_leg_and_next_task_are_self_transitions():
    assert next_state(State.MOTION, Event.MOVE) == State.MOTION
    assert next_state(State.WORK, Event.WORK) == State.WORK


def test_the_plain_states_are_the_models_states():
    """One enum: the model's choices are built from fleetcore.states.State."""
    from fleetcore.states import State
    from robots.models import Robot

    assert [s.value for s in State] == list(Robot.State.values)
