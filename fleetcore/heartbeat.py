"""A process's heartbeat: a file whose modification time its main loop renews, so that a watcher can tell a hung
process (stopped, or its event loop blocked) from a live one (fleet/hangwatch.py watches them under `make run`).

    beat = heartbeat.from_env()          # FLEET_HEARTBEAT names the file; None when unset (nothing is watched)
    task = beat.start_task()             # from an event loop: renewed by that loop every PERIOD seconds
    beat.beat()                          # or from a plain loop, once per pass

A file, not a Redis key: it needs nothing running to be written (a process waiting out a Redis outage is not
taken for hung), and renewing it (utime) needs no free disk space. A failure to write is logged once, never raised.
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
from pathlib import Path

ENV = "FLEET_HEARTBEAT"
PERIOD = 0.25  # seconds between beats: well under the watcher's first bound (1 s)

log = logging.getLogger(__name__)


class Heartbeat:
    """The heartbeat file of one process."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.failed = False

    def beat(self) -> None:
        """Renew the file's time (made if missing)."""
        try:
            try:
                os.utime(self.path)
            except FileNotFoundError:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.path.touch()
            self.failed = False
        except OSError as exc:
            if not self.failed:
                log.warning("heartbeat %s not written: %s", self.path, exc)
            self.failed = True

    async def run(self, period: float = PERIOD) -> None:
        """Beat from the running event loop until cancelled: a blocked loop stops the beats."""
        while True:
            self.beat()
            await asyncio.sleep(period)

    def start_task(self, period: float = PERIOD) -> asyncio.Task:
        return asyncio.get_running_loop().create_task(self.run(period), name="heartbeat")

    def start_thread(self, period: float = PERIOD) -> threading.Thread:
        """Beat from a daemon thread: says the process runs (not stopped, not holding the GIL), not that a
        particular loop of it turns; for processes whose main loop may rightly wait (a Celery worker's consumer
        reconnecting to its broker)."""

        def _run() -> None:
            stop = threading.Event()
            while not stop.wait(period):
                self.beat()

        self.beat()
        thread = threading.Thread(target=_run, name="heartbeat", daemon=True)
        thread.start()
        return thread


def from_env(environ=os.environ) -> Heartbeat | None:
    """The heartbeat the supervisor asked of this process, or None."""
    path = environ.get(ENV)
    return Heartbeat(Path(path)) if path else None
