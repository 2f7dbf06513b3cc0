"""The per-robot state machine of the paper's Figures 5 and 6, as plain data (no Django).

States: registered -> ready; ready -> dialog -> motion -> work -> ready; offline after the link drops or the
idle timeout. Priorities: work > motion > dialog > ready. A new instruction preempts only an activity of lower
priority than its own; otherwise it queues behind it.
"""

from __future__ import annotations

from enum import StrEnum


class State(StrEnum):
    """The robot states; the values match robots.models.Robot.State."""

    REGISTERED = "registered"
    READY = "ready"
    DIALOG = "dialog"
    MOTION = "motion"
    WORK = "work"
    OFFLINE = "offline"


class Event(StrEnum):
    """What can happen to a robot."""

    LINK_UP = "link_up"
    LINK_DOWN = "link_down"
    IDLE_TIMEOUT = "idle_timeout"
    ASK = "ask"  # the instruction needs an answer from a person
    MOVE = "move"  # start moving to a destination
    WORK = "work"  # start a task at the destination
    DONE = "done"  # the instruction (or this robot's share of it) finished
    STOP = "stop"
    FAIL = "fail"
    PREEMPT = "preempt"  # a higher-priority instruction interrupts this one


class IllegalTransition(ValueError):
    """The event cannot happen in the robot's current state."""


S, E = State, Event
ACTIVE = (S.DIALOG, S.MOTION, S.WORK)

# event -> {from state: to state}. Anything not listed is illegal.
TRANSITIONS: dict[Event, dict[State, State]] = {
    E.LINK_UP: {S.REGISTERED: S.READY, S.OFFLINE: S.READY},
    E.LINK_DOWN: {state: S.OFFLINE for state in (S.REGISTERED, S.READY, *ACTIVE)},
    E.IDLE_TIMEOUT: {S.READY: S.OFFLINE},
    E.ASK: {S.READY: S.DIALOG},
    # motion -> motion: the next leg ("to D then E"); work -> work: the next task. Both are stored.
    E.MOVE: {S.READY: S.MOTION, S.DIALOG: S.MOTION, S.WORK: S.MOTION, S.MOTION: S.MOTION},
    E.WORK: {S.READY: S.WORK, S.DIALOG: S.WORK, S.MOTION: S.WORK, S.WORK: S.WORK},
    E.DONE: {state: S.READY for state in ACTIVE},
    E.STOP: {state: S.READY for state in ACTIVE},
    E.FAIL: {state: S.READY for state in ACTIVE},
    E.PREEMPT: {state: S.READY for state in ACTIVE},
}

PRIORITY: dict[State, int] = {S.READY: 0, S.DIALOG: 1, S.MOTION: 2, S.WORK: 3}


def next_state(state: str, event: str) -> State:
    """The state after the event, or IllegalTransition naming both."""
    try:
        return TRANSITIONS[Event(event)][State(state)]
    except (KeyError, ValueError):
        raise IllegalTransition(f"no transition from {state!r} on {event!r}") from None


def can(state: str, event: str) -> bool:
    """Whether the event is legal in this state."""
    try:
        next_state(state, event)
    except IllegalTransition:
        return False
    return True


class Admission(StrEnum):
    START = "start"  # the robot is ready: run now
    PREEMPT = "preempt"  # interrupt the robot's lower-priority activity
    QUEUE = "queue"  # wait behind an activity of equal or higher priority
    REFUSE = "refuse"  # the robot cannot take instructions (offline, not yet ready)


def admit(state: str, priority: int) -> Admission:
    """Decide what a new instruction of this priority does to a robot in this state."""
    state = State(state)
    if state in (S.OFFLINE, S.REGISTERED):
        return Admission.REFUSE
    if state == S.READY:
        return Admission.START
    return Admission.PREEMPT if priority > PRIORITY[state] else Admission.QUEUE
