"""Run a world in the foreground until SIGINT / SIGTERM (management command and Celery task)."""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import Callable

from fleetcore import heartbeat
from simworker.fleet import SimFleet


def serve_world(
    world: str = "paper",
    host: str = "127.0.0.1",
    port_base: int | None = 9090,
    extra: int = 0,
    time_scale: float = 1.0,
    keep_last_command: bool = False,
    out: Callable[[str], None] = print,
    endpoints: list[str] | None = None,
    extra_skip: int = 0,
    extra_spacing: float | None = None,
) -> dict:
    """Serve the world (only these endpoints, if given: a shard), print one line per endpoint when ready,
    return the loop's stats when stopped."""
    fleet = SimFleet(
        world,
        host,
        port_base,
        extra,
        endpoints,
        time_scale=time_scale,
        keep_last_command=keep_last_command,
        extra_skip=extra_skip,
        extra_spacing=extra_spacing,
    )
    if not fleet.servers:
        raise ValueError(f"no endpoint of world {world!r} to serve among {', '.join(endpoints or [])}")

    beating = []  # the heartbeat's task, kept while the loop runs

    def ready(f: SimFleet) -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(ValueError, RuntimeError):  # not the main thread (e.g. a worker pool)
                loop.add_signal_handler(sig, f.request_stop)
        beat = heartbeat.from_env()
        if beat is not None:  # renewed by the physics' own loop: a blocked loop is seen as hung
            beating.append(beat.start_task())
        for key, url in f.urls.items():
            out(f"simworker: {key} ready at {url}")

    asyncio.run(fleet.run(on_ready=ready))
    out(f"simworker: stopped after {fleet.stats.steps} steps")
    return {"steps": fleet.stats.steps, "late_steps": fleet.stats.late_steps, "urls": fleet.urls}
