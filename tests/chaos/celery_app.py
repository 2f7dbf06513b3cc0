"""The fleet's Celery app (its broker settings and Redis transport) with one task that holds a worker for a while,
for the broker-loss test: `celery -A tests.chaos.celery_app worker -Q chaos`."""

import time
from pathlib import Path

from fleet.celery import app

__all__ = ["app", "hold"]


@app.task(name="tests.chaos.hold", ignore_result=True)
def hold(seconds: float, marks: str) -> None:
    """Stand for a task that runs through a broker outage (as an instruction drives robots): say when it started
    and when it ended in files under `marks`."""
    Path(marks, "started").write_text("")
    time.sleep(seconds)
    Path(marks, "ended").write_text("")
