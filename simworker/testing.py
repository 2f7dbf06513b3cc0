"""Run a simulated world in a background thread, or in a child process, for tests and scripts.

with running_world("paper") as sim:
    url = sim.urls["turtlebot"]       # ws://127.0.0.1:<free port>
    x, y, yaw = sim.pose("turtlebot")

WorldProcess runs the same world in a process of its own, so that a busy caller (a bench driving dozens of
robots) and the physics loop do not share one interpreter's lock:

with WorldProcess("warehouse", time_scale=2.0) as sim:
    sim.urls, sim.pose("husky1"), sim.contacts(), sim.home(["husky1"])
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import multiprocessing
import signal
import socket
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from multiprocessing.connection import Connection

from simworker.fleet import SimFleet

START_TIMEOUT = 10.0  # s: a world in a thread is up
PROCESS_START_TIMEOUT = 60.0  # s: a world in a spawned process is up (it imports the simulator afresh)
REPLY_TIMEOUT = 5.0  # s: the world process answers a request
STOP_TIMEOUT = 10.0  # s: the world process ends after SIGTERM (then after SIGKILL)
READY = 0  # the sequence number of the world process's first message: its URLs, or why it did not start


def send_home(fleet: SimFleet, names: Iterable[str]) -> None:
    """Teleport robots back to their start poses, at rest (call from the fleet's loop). Their odometry
    moves with them: it is measured from the start pose."""
    for name in names:
        body = fleet.robots[name].body.body
        x, y, yaw = fleet.robots[name].start
        body.position, body.angle, body.velocity, body.angular_velocity = (x, y), yaw, (0, 0), 0.0
        fleet.physics.space.reindex_shapes_for_body(body)


def bad_odometry(fleet: SimFleet, name: str, fault: str | None) -> None:
    """Make a robot publish bad odometry ("nan": x is NaN, "jump": 1 km off), or good again with None."""
    fleet.robots[name].odom_fault = fault


def contact_count(fleet: SimFleet) -> int:
    """Robot-robot contacts the physics has counted so far."""
    return len(fleet.physics.contacts)


def touched(fleet: SimFleet, since: int = 0) -> list[tuple[float, str, str]]:
    """The contacts counted so far from the since-th on: (simulated time, robot, robot)."""
    return [(round(c.t, 1), c.a, c.b) for c in fleet.physics.contacts[since:]]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now (another process may take it before it is bound:
    a server of the test's own is better started on bound_socket())."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def bound_socket() -> tuple[socket.socket, int]:
    """A TCP socket bound to a free port of 127.0.0.1, and that port: a server given it (uvicorn's
    `Server.run(sockets=[sock])`) listens where nothing else can have bound in between."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    return sock, sock.getsockname()[1]


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


# What the world process answers: request name -> fn(fleet, *args), run on the fleet's loop.
REQUESTS = {
    "pose": SimFleet.pose, "contacts": contact_count, "touched": touched, "home": send_home, "odometry": bad_odometry,
}  # fmt: skip


class WorldProcess:
    """A world run in a child process ("spawn": no Django state or threads of the caller's are inherited).

    Requests go over a pipe as (sequence number, name, args) and come back as (sequence number, ok, value);
    a lock lets several threads share the handle, and a reply that comes after its request timed out is
    skipped by its sequence number.
    """

    def __init__(self, world: str = "paper", **options) -> None:
        """options as running_world's (host, port_base, extra, endpoints, time_scale, SimFleet's options)."""
        self.world, self.options = world, options
        self.urls: dict[str, str] = {}
        self.process: multiprocessing.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._lock = threading.Lock()
        self._seq = READY

    def __enter__(self) -> WorldProcess:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()

    def start(self) -> WorldProcess:
        """Start the child and wait (bounded) for its servers to listen; raise RuntimeError if they do not."""
        context = multiprocessing.get_context("spawn")
        self._conn, child_end = context.Pipe()
        self.process = context.Process(
            target=serve_world, args=(child_end, self.world, self.options), name="simworker", daemon=True
        )
        self.process.start()
        child_end.close()  # only the child holds it now: its death shows here as the end of the pipe
        try:
            self.urls = self._reply(READY, "start", PROCESS_START_TIMEOUT)
        except BaseException:
            self.stop()
            raise
        return self

    def pose(self, robot: str) -> tuple[float, float, float]:
        """Return the ground-truth (x, y, yaw) of a robot in the map frame."""
        return self._request("pose", robot)

    def contacts(self) -> int:
        """Robot-robot contacts the physics has counted since the world started."""
        return self._request("contacts")

    def touched(self, since: int = 0) -> list[tuple[float, str, str]]:
        """Which robots touched, and when (simulated s): the contacts from the since-th on."""
        return self._request("touched", since)

    def home(self, names: Iterable[str]) -> None:
        """Teleport these robots back to their start poses (send_home)."""
        self._request("home", list(names))

    def _request(self, name: str, *args):
        with self._lock:
            self._seq += 1
            self._conn.send((self._seq, name, args))
            return self._reply(self._seq, name, REPLY_TIMEOUT)

    def _reply(self, seq: int, name: str, timeout: float):
        """The value of reply `seq` (older replies skipped); raise if it failed, or does not come in time."""
        deadline = time.monotonic() + timeout
        while self._conn.poll(max(0.0, deadline - time.monotonic())):
            try:
                got, ok, value = self._conn.recv()
            except EOFError:
                raise RuntimeError(f"world process: {name}: the process ended") from None
            if got == seq:
                if not ok:
                    raise RuntimeError(f"world process: {name}: {value}")
                return value
        raise TimeoutError(f"world process: {name}: no answer within {timeout:g} s")

    def stop(self) -> None:
        """SIGTERM the child (its loop closes the servers), SIGKILL it if it lingers; idempotent."""
        if self.process is not None and self.process.pid is not None:
            self.process.terminate()
            self.process.join(STOP_TIMEOUT)
            if self.process.is_alive():
                self.process.kill()
                self.process.join(STOP_TIMEOUT)
        if self._conn is not None:
            self._conn.close()
            self._conn = None


def serve_world(conn: Connection, world: str, options: dict) -> None:
    """The world process: run the fleet; answer requests on its loop; SIGTERM or SIGINT stops it cleanly."""
    try:
        fleet = SimFleet(world, **options)
        asyncio.run(fleet.run(on_ready=lambda running: _serve_ready(running, conn)))
    except BaseException as exc:  # before READY, the parent's start() reports it; after, it sees the pipe end
        with suppress(OSError):  # the parent may have gone
            conn.send((READY, False, repr(exc)))
        raise


def _serve_ready(fleet: SimFleet, conn: Connection) -> None:
    """The servers listen: stop on signals, answer requests, tell the parent the URLs."""
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, fleet.request_stop)
    loop.add_reader(conn.fileno(), _answer, fleet, conn)
    conn.send((READY, True, fleet.urls))


def _answer(fleet: SimFleet, conn: Connection) -> None:
    """Answer one request from the pipe; stop the fleet when the parent has gone."""
    try:
        seq, name, args = conn.recv()
    except EOFError:
        asyncio.get_running_loop().remove_reader(conn.fileno())
        fleet.request_stop()
        return
    try:
        reply = (seq, True, REQUESTS[name](fleet, *args))
    except Exception as exc:  # the caller's error (an unknown robot), not the world's
        reply = (seq, False, repr(exc))
    conn.send(reply)
