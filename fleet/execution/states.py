"""Robot state changes as the database sees them: every transition stored with its reason and pushed live."""

from __future__ import annotations

import logging

from django.db import transaction
from django.utils import timezone

from fleet import live
from fleet.models import StateTransition
from fleet.statemachine import IllegalTransition, next_state
from robots.models import Robot

log = logging.getLogger(__name__)


@transaction.atomic
def transition(robot: Robot | int, event: str, reason: str = "", instruction=None) -> StateTransition | None:
    """Apply an event to a robot's state; store and push the transition. None when the event is illegal now."""
    robot_id = robot if isinstance(robot, int) else robot.pk
    current = Robot.objects.select_for_update().get(pk=robot_id)
    try:
        to_state = next_state(current.state, event)
    except IllegalTransition as exc:
        log.info("%s: %s (%s)", current.name, exc, reason)
        return None
    return _store(current, to_state, reason, instruction)


@transaction.atomic
def force(robot: Robot | int, to_state: str, reason: str, instruction=None) -> StateTransition | None:
    """Set a state whatever the current one (recovery after a lost worker); None if already there."""
    robot_id = robot if isinstance(robot, int) else robot.pk
    current = Robot.objects.select_for_update().get(pk=robot_id)
    if current.state == to_state:
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
    Robot.objects.filter(pk=robot.pk).update(state=to_state)
    robot.state = to_state
    live.transition(robot, record)
    live.robot_status(robot)
    return record
