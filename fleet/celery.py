"""The Celery app: queues per concern (instructions, control, registration, sim)."""

import os

from celery import Celery
from celery.signals import worker_process_init

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")

app = Celery("fleet")
app.config_from_object("django.conf:settings", namespace="CELERY")
app.autodiscover_tasks()


@worker_process_init.connect
def load_heavy_state(**_kwargs):
    """Load the ontology once per worker process, never at import time."""
    from interpreter.service import warm_up

    warm_up()
