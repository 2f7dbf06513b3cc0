"""Recordings run on the instructions worker (a thread pool: a recording waits most of its time)."""

from celery import shared_task

from recordings import recorder


@shared_task(name="recordings.tasks.record", acks_late=True)
def record(recording_pk: int) -> str:
    return recorder.run(recording_pk).status
