"""The fleet portal: the Django project and the fleet-wide domain."""

from fleet.celery import app as celery_app

__all__ = ["celery_app"]
