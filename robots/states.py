"""Robot state changes as the database sees them: every transition stored with its reason and pushed live."""

from __future__ import annotations

import logging

from django.utils import timezone

import live
from fleetcore.states import IllegalTransition, next_state
from robots.models import Robot, StateTransition

log = logging.getLogger(__name__)


def transition(robot: Robot | int, event: str, reason: str = "", instruction=None) -> StateTransition | None:
    """Apply an event to a robot's state; store and push the transition. None when the event is illegal now.

    A compare-and-set on the state (no read-then-write transaction), so concurrent runners never interleave.
    """
    robot_id = robot if isinstance(robot, int) else robot.pk
    for _ in range(5):
        current = Robot.objects.get(pk=robot_id)
        try:
            to_state = next_state(current.state, event)
        except IllegalTransition as exc:
            log.info("%s: %s (%s)", current.name, exc, reason)
            return None
        if Robot.objects.filter(pk=robot_id, state=current.state).update(state=to_state):
            return _store(current, to_state, reason, instruction)
    return None


def force(robot: Robot | int, to_state: str, reason: str, instruction=None) -> StateTransition | None:
    """Set a state whatever the current one (recovery); None if already there."""
    robot_id = robot if isinstance(robot, int) else robot.pk
    current = Robot.objects.get(pk=robot_id)
    if current.state == to_state or not Robot.objects.filter(pk=robot_id, state=current.state).update(
        state=to_state
    ):
        return None
    return _store(current, to_state, reason, instruction)


def _store(robot: Robot, to_state: str, reason: str, instruction) -> StateTransition:
    record = StateTransition.objects.create(
        robot=robot,
        from_state=robot.state,
        to_state=to_state,
        at=timezone.now(),
        reason=reason[:255],
        instruction_id=instruction if isinstance(instruction, int) else getattr(instruction, "pk", None),
    )
    robot.state = to_state
    live.transition(robot, record)
    live.robot_status(robot)
    return record
