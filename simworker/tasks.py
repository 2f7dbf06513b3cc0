"""Celery tasks of the simulator: one world per worker process, on the `sim` queue."""

from __future__ import annotations

from celery import shared_task

from simworker.runner import serve_world


@shared_task(name="simworker.tasks.run_world", queue="sim", acks_late=False)
def run_world(world: str = "paper", host: str = "0.0.0.0", port_base: int = 9090, extra: int = 0) -> dict:
    """Serve a world for the life of this worker process (until it is stopped)."""
    return serve_world(world, host, port_base, extra)
