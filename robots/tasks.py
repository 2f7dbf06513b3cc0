"""Celery tasks of the robots app: thin wrappers over robots.registration."""

from celery import shared_task
from django.contrib.auth import get_user_model

from robots.registration import register_endpoints as register


@shared_task(name="robots.tasks.register_endpoints")
def register_endpoints(
    urls: list[str], user_id: int | None = None, record_ids: list[int] | None = None
) -> list[dict]:
    """Register endpoints for a user, filling the records begun for them; one {url, ok, error, robots} each."""
    user = get_user_model().objects.filter(pk=user_id).first() if user_id else None
    return [
        {"url": r.url, "ok": r.ok, "error": r.error, "robots": r.robots, "record": r.record_id}
        for r in register(urls, user=user, record_ids=record_ids)
    ]
