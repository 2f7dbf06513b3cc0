"""Celery tasks of the execution app: thin, idempotent, taking primary keys (queue: control). Instructions run
in the executor processes (execution/executor.py), not here."""

from celery import shared_task
from django.contrib.auth import get_user_model

from execution.control import stop


@shared_task(name="execution.tasks.stop_robots", acks_late=True, ignore_result=True)
def stop_robots(robot_ids: list[int], user_id: int | None = None) -> dict:
    """Stop robots from a worker (for callers that cannot reach the endpoints themselves)."""
    user = get_user_model().objects.filter(pk=user_id).first() if user_id else None
    return stop(robot_ids, user, source="task")
