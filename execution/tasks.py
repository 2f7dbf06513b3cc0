"""Celery tasks of the fleet: thin, idempotent, taking primary keys (queues: instructions, control)."""

from celery import shared_task

from execution import runner, watchdog


@shared_task(name="execution.tasks.execute_instruction", acks_late=True, ignore_result=True)
def execute_instruction(instruction_id: int) -> list[int]:
    """Run an instruction's executions; a redelivery finds them claimed or finished and does nothing twice."""
    from execution.models import Execution

    robot_ids = Execution.objects.filter(instruction_id=instruction_id).values_list("robot_id", flat=True)
    watchdog.recover(set(robot_ids))
    return runner.execute_instruction(instruction_id)


@shared_task(name="execution.tasks.drain_robot", acks_late=True, ignore_result=True)
def drain_robot(robot_id: int) -> bool:
    """Run a robot's waiting executions if no runner holds it."""
    return runner.drain_robot(robot_id)


@shared_task(name="execution.tasks.stop_robots", acks_late=True, ignore_result=True)
def stop_robots(robot_ids: list[int], user_id: int | None = None) -> dict:
    """Stop robots from a worker (for callers that cannot reach the endpoints themselves)."""
    from django.contrib.auth import get_user_model

    from execution.control import stop

    user = get_user_model().objects.filter(pk=user_id).first() if user_id else None
    return stop(robot_ids, user, source="task")
