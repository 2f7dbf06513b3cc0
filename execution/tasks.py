"""Celery tasks of the fleet: thin, idempotent, taking primary keys (queues: instructions, control)."""

from celery import shared_task
from django.contrib.auth import get_user_model

from execution import runner
from execution.control import stop


@shared_task(name="execution.tasks.drain_robot", acks_late=True, ignore_result=True)
def drain_robot(robot_id: int) -> bool:
    """The robot's executor: run its waiting executions in order, unless another runner holds its lock.

    One task per robot per wake-up (dispatch sends one for each robot of an instruction; the watchdog one
    for a robot whose queue stalled); a redelivery finds the executions claimed or finished and does nothing.
    """
    return runner.drain_robot(robot_id)


@shared_task(name="execution.tasks.stop_robots", acks_late=True, ignore_result=True)
def stop_robots(robot_ids: list[int], user_id: int | None = None) -> dict:
    """Stop robots from a worker (for callers that cannot reach the endpoints themselves)."""
    user = get_user_model().objects.filter(pk=user_id).first() if user_id else None
    return stop(robot_ids, user, source="task")
