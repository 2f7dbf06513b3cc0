"""Run a simulated world in a background thread, for tests and scripts.

with running_world("paper") as sim:
    url = sim.urls["turtlebot"]       # ws://127.0.0.1:<free port>
    x, y, yaw = sim.pose("turtlebot")
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import socket
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager

from simworker.fleet import SimFleet

START_TIMEOUT = 10.0


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class RunningWorld:
    """Handle on a fleet running in its own thread and event loop."""

    def __init__(self, fleet: SimFleet) -> None:
        self.fleet = fleet
        self.loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="simworker", daemon=True)

    @property
    def urls(self) -> dict[str, str]:
        """Endpoint key -> ws:// URL (e.g. robots, turtlebot, husky, tiago, spot, tb3_nav2, extra)."""
        return self.fleet.urls

    def _run(self) -> None:
        try:
            asyncio.run(self.fleet.run(on_ready=self._on_ready))
        except BaseException as exc:  # reported to the starting thread
            self._error = exc
            self._ready.set()

    def _on_ready(self, fleet: SimFleet) -> None:
        self.loop = asyncio.get_running_loop()
        self._ready.set()

    def start(self) -> RunningWorld:
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT) or self._error is not None:
            raise RuntimeError(f"simulated world did not start: {self._error!r}")
        return self

    def call(self, fn, *args):
        """Run fn(*args) on the simulator's loop and return its result (thread-safe)."""
        future: concurrent.futures.Future = concurrent.futures.Future()

        def run() -> None:
            try:
                future.set_result(fn(*args))
            except BaseException as exc:
                future.set_exception(exc)

        self.loop.call_soon_threadsafe(run)
        return future.result(timeout=5)

    def pose(self, robot: str) -> tuple[float, float, float]:
        """Return the ground-truth (x, y, yaw) of a robot in the map frame."""
        return self.call(self.fleet.pose, robot)

    def stop(self) -> None:
        """Stop the loop, close the servers and join the thread (idempotent)."""
        if self.loop is not None and self._thread.is_alive():
            self.loop.call_soon_threadsafe(self.fleet.request_stop)
            self._thread.join(timeout=10)


@contextmanager
def running_world(
    world: str = "paper",
    host: str = "127.0.0.1",
    port_base: int | None = None,
    extra: int = 0,
    endpoints: Iterable[str] | None = None,
    time_scale: float = 1.0,
    **options,
) -> Iterator[RunningWorld]:
    """Run a world for the duration of the block; port_base None picks free ports."""
    handle = RunningWorld(SimFleet(world, host, port_base, extra, endpoints, time_scale, **options)).start()
    try:
        yield handle
    finally:
        handle.stop()
