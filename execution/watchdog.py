"""Find executions whose worker died, stop their robots and fail them; restart robots' stalled queues.

A running execution carries the token of the runner that claimed it, and that runner holds the robot's lock
with the same token, renewing it every half second. When the lock is gone (or held by another token), the
runner is gone: the robot gets a zero velocity, the execution is marked failed (never resumed silently: a
robot that starts moving by itself after a crash is the worse surprise) and its instruction is settled.
"""

from __future__ import annotations

import logging
from datetime import timedelta

from django.utils import timezone

from execution import coordination
from execution.link import publish_zero
from execution.models import Execution
from execution.runner import WAITING, settle
from fleetcore.states import Event
from robots.models import Robot

log = logging.getLogger(__name__)
STALLED_AFTER = 3.0  # s a queued execution may wait for its task before the robot is kicked
LOST = "the worker running it was lost; the robot was stopped"


def recover(robot_ids=None) -> list[int]:
    """Fail running executions without a live runner; return their primary keys."""
    running = Execution.objects.filter(status=Execution.Status.RUNNING).select_related("robot")
    if robot_ids is not None:
        running = running.filter(robot_id__in=list(robot_ids))
    failed = []
    for execution in running:
        if coordination.lock_holder(execution.robot_id) == execution.worker:
            continue
        won = Execution.objects.filter(
            pk=execution.pk, status=Execution.Status.RUNNING, worker=execution.worker
        ).update(status=Execution.Status.FAILED, finished_at=timezone.now(), error=LOST)
        if not won:
            continue
        failed.append(execution.pk)
        try:
            publish_zero(execution.robot)
        except Exception as exc:  # report, and still settle the instruction
            log.warning("%s: could not stop after a lost worker: %s", execution.robot.name, exc)
        Robot.objects.transition(execution.robot_id, Event.FAIL, LOST, execution.instruction_id)
        settle(execution.instruction_id)
    return failed


def stalled_robots() -> list[int]:
    """Robots with waiting executions and nobody holding their lock."""
    settled = timezone.now() - timedelta(seconds=STALLED_AFTER)  # give the task its time to be picked up
    waiting = Execution.objects.filter(status__in=WAITING, created_at__lt=settled)
    robot_ids = set(waiting.values_list("robot_id", flat=True))
    return sorted(rid for rid in robot_ids if coordination.lock_holder(rid) is None)


def kick_stalled() -> list[int]:
    """Send a drain task for each stalled robot (at most one every few seconds per robot)."""
    from execution.dispatch import launch

    kicked = []
    for robot_id in stalled_robots():
        if coordination.connection().set(coordination.key("kick", robot_id), 1, nx=True, ex=5):
            launch("drain_robot", robot_id)
            kicked.append(robot_id)
    return kicked
