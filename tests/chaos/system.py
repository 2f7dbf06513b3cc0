"""The whole system as `make run` starts it, in a folder and on ports of its own, for the chaos tests.

`make run` runs under a pseudo-terminal, as a person runs it, so its Ctrl-C is the terminal's. Its processes are
found and watched through the supervisor's RPC interface (what `supervisorctl` uses).
"""

from __future__ import annotations

import http.cookiejar
import itertools
import json
import math
import os
import pty
import random
import re
import signal
import socket
import sqlite3
import subprocess
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
import xmlrpc.client
from collections import deque
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

import psutil

from fleet.supervision import Layout, rpc

BASE_DIR = Path(__file__).resolve().parents[2]
PASSWORD = "chaos-monkey-password"
SIM_PORTS = 7  # the demo world's endpoints: offsets 0..6 from the base
START_TIMEOUT = (
    180.0  # s for `make run` to have every process up and the portal answering (a loaded 2-core box)
)
STOP_TIMEOUT = 60.0
LOGIN_TIMEOUT = 30.0  # s for the login page and form (a loaded machine; a page load's own limit is below)


def free_port_block(count: int, attempts: int = 50) -> int:
    """The first of `count` consecutive TCP ports on 127.0.0.1 that are all free now."""
    for _ in range(attempts):
        base = random.randint(20000, 60000 - count)
        if all(_free(port) for port in range(base, base + count)):
            return base
    raise RuntimeError(f"no {count} consecutive free ports found in {attempts} tries")


def _free(port: int) -> bool:
    with socket.socket() as sock:
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
        return True


@dataclass
class Process:
    """One supervised process as the supervisor sees it now."""

    name: str  # the program's name (web, worker, redis, ...)
    state: str
    pid: int


@dataclass
class RunningSystem:
    """`make run` in a pseudo-terminal, with its own var folder, port and simulator ports."""

    var_dir: Path
    port: int = field(default_factory=lambda: free_port_block(1))
    sim_port_base: int = field(default_factory=lambda: free_port_block(SIM_PORTS))
    make: subprocess.Popen | None = None
    terminal: int | None = None  # the pseudo-terminal's controlling side
    output: bytearray = field(default_factory=bytearray)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    @property
    def layout(self) -> Layout:
        return Layout(self.var_dir)

    def env(self) -> dict[str, str]:
        """Ours, less what would point it at the test run's Redis, database or make's jobserver."""
        dropped = {"REDIS_URL", "DATABASE_URL", "FLEET_REDIS_PREFIX", "MAKEFLAGS", "MFLAGS", "MAKELEVEL"}
        env = {key: value for key, value in os.environ.items() if key not in dropped}
        return env | {
            "FLEET_VAR_DIR": str(self.var_dir),
            "FLEET_PORT": str(self.port),
            "FLEET_SIM_PORT_BASE": str(self.sim_port_base),
            "FLEET_ADMIN_PASSWORD": PASSWORD,
            # a robot at rest after a fault is then the portal's doing, not its base's cmd_vel timeout
            "FLEET_SIM_OPTIONS": "--keep-last-command",
        }

    # ----- start and stop -----
    def start(self) -> RunningSystem:
        """`make run` (its install step taken as done: `make test` has just done it), until all is up."""
        controller, child = pty.openpty()
        self.terminal = controller
        self.make = subprocess.Popen(
            ["make", "--no-print-directory", "-o", ".venv/.installed", "run"],
            cwd=BASE_DIR,
            env=self.env(),
            stdin=child,
            stdout=child,
            stderr=child,
            start_new_session=True,  # a session whose controlling terminal is this pty, as a shell gives
            preexec_fn=_take_terminal,
        )
        os.close(child)
        threading.Thread(target=self._read_terminal, name="make run's terminal", daemon=True).start()
        self.wait_until(lambda: b"Fleet portal ready" in self.output, START_TIMEOUT, "the portal ready line")
        self.wait_until(self.all_running, START_TIMEOUT, "every process running")
        return self

    def _read_terminal(self) -> None:
        """Keep reading what `make run` prints, so that it never blocks on a full terminal."""
        while True:
            try:
                data = os.read(self.terminal, 65536)
            except OSError:
                return  # the terminal closed: make and everything under it ended
            if not data:
                return
            self.output += data

    def interrupt(self) -> int:
        """Ctrl-C on the terminal, as a person presses it; make's exit status."""
        os.write(self.terminal, b"\x03")
        try:
            return self.make.wait(timeout=STOP_TIMEOUT)
        finally:
            self.kill_leftovers()

    def kill_leftovers(self) -> None:
        """If make did not end, end what it started (its session), so nothing outlives the test."""
        if self.make and self.make.poll() is None:
            os.killpg(self.make.pid, signal.SIGKILL)
            self.make.wait(timeout=10)
        if self.terminal is not None:
            os.close(self.terminal)
            self.terminal = None

    def text(self) -> str:
        return self.output.decode("utf-8", "replace")

    # ----- the supervisor's view -----
    def processes(self) -> dict[str, Process]:
        """Every supervised process by program name."""
        infos = rpc(self.layout).supervisor.getAllProcessInfo()
        return {info["name"]: Process(info["name"], info["statename"], info["pid"]) for info in infos}

    def all_running(self) -> bool:
        try:
            return all(process.state == "RUNNING" for process in self.processes().values())
        except (OSError, xmlrpc.client.Error):
            return False

    def kill(self, name: str) -> int:
        """kill -9 one process, and wait until it has ended (no longer answers, holds no port); its pid."""
        pid = self.processes()[name].pid
        os.kill(pid, signal.SIGKILL)
        self.wait_until(lambda: not alive(pid), 5.0, f"{name} (pid {pid}) ended after SIGKILL")
        return pid

    def back(self, name: str, old_pid: int) -> bool:
        """Whether the process runs again under a new pid (the supervisor's RUNNING: up for START_SECONDS)."""
        try:
            process = self.processes()[name]
        except (OSError, xmlrpc.client.Error):
            return False
        return process.state == "RUNNING" and process.pid not in (0, old_pid)

    def beating(self, name: str, within: float = 1.0) -> bool:
        """Whether the process has renewed its heartbeat file within the last `within` seconds."""
        try:
            return time.time() - self.layout.beat(name).stat().st_mtime < within
        except FileNotFoundError:
            return False  # not beaten since its start

    # ----- the portal, as a logged-in person sees it -----
    def browser(self) -> urllib.request.OpenerDirector:
        """A logged-in session (the demo admin) whose redirects are not followed."""
        jar = http.cookiejar.CookieJar()
        opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(jar), _NoRedirect())
        with opener.open(f"{self.url}login/", timeout=LOGIN_TIMEOUT) as page:
            token = re.search(rb'name="csrfmiddlewaretoken" value="([^"]+)"', page.read())[1].decode()
        form = urllib.parse.urlencode(
            {"username": "admin", "password": PASSWORD, "csrfmiddlewaretoken": token}
        )
        request = urllib.request.Request(
            f"{self.url}login/", data=form.encode(), headers={"Referer": self.url}
        )
        try:
            opener.open(request, timeout=LOGIN_TIMEOUT)
        except urllib.error.HTTPError as answer:
            assert answer.code == 302, f"login answered {answer.code}"
        opener.csrf_token = next(cookie.value for cookie in jar if cookie.name == "csrftoken")
        return opener

    # ----- instructions -----
    def instruct(self, text: str) -> int:
        """Submit an instruction as the console does without its socket (POST /api/instructions); its id."""
        opener = self.browser()
        headers = {"Content-Type": "application/json", "X-CSRFToken": opener.csrf_token, "Referer": self.url}
        body = json.dumps({"text": text}).encode()
        request = urllib.request.Request(f"{self.url}api/instructions", data=body, headers=headers)
        with opener.open(request, timeout=60) as answer:
            return json.loads(answer.read())["id"]

    def instructions(self, where: str = "", *args) -> list[tuple[int, str, str]]:
        """(id, status, outcome) of instructions, from the database itself (the web server may be the one
        killed): `where` is an SQL condition on execution_instruction."""
        database = f"file:{self.var_dir / 'fleet.sqlite3'}?mode=ro"
        query = "SELECT id, status, outcome FROM execution_instruction" + (f" WHERE {where}" if where else "")
        with closing(sqlite3.connect(database, uri=True, timeout=10)) as db:
            return db.execute(query + " ORDER BY id", args).fetchall()

    def instruction(self, pk: int) -> tuple[str, str]:
        """(status, outcome) of one instruction."""
        ((_, status, outcome),) = self.instructions("id = ?", pk)
        return status, outcome

    def times_until(self, conditions: dict, timeout: float, since: float | None = None) -> list[float]:
        """Seconds from `since` (time.monotonic(); default now) until each condition (named by what it waits
        for) first held, checked together."""
        start, times = time.monotonic() if since is None else since, {}
        while len(times) < len(conditions) and time.monotonic() - start < timeout:
            for what, condition in conditions.items():
                if what not in times and condition():
                    times[what] = time.monotonic() - start
            time.sleep(0.05)
        missing = [what for what in conditions if what not in times]
        assert not missing, (
            f"not within {timeout:g} s: {', '.join(missing)}\n--- make run ---\n{self.text()[-4000:]}"
        )
        return [times[what] for what in conditions]

    def wait_until(self, condition, timeout: float, what: str) -> float:
        """Seconds until condition() held; AssertionError (with make's last output) if it did not in time."""
        start = time.monotonic()
        while time.monotonic() - start < timeout:
            if condition():
                return time.monotonic() - start
            if self.make is not None and self.make.poll() is not None:
                break
            time.sleep(0.1)
        raise AssertionError(
            f"not within {timeout:g} s: {what}\n--- make run said ---\n{self.text()[-4000:]}"
        )


def alive(pid: int) -> bool:
    """Whether the process runs (a zombie has ended: only its exit status is left to collect)."""
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *args, **kwargs):
        return None  # a 302 is an answer here


def _take_terminal() -> None:
    """In the child, a session leader by now: its stdin, the pty, becomes its controlling terminal."""
    import fcntl
    import termios

    fcntl.ioctl(0, termios.TIOCSCTTY, 0)


@dataclass
class Requests:
    """A person's page loads while a fault lasts: GET / every `period` s from a logged-in session."""

    system: RunningSystem
    period: float = 0.25
    sent: int = 0
    failed: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.opener = self.system.browser()
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, name="page loads", daemon=True)

    def __enter__(self) -> Requests:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.done.set()
        self.thread.join(timeout=15)

    def _run(self) -> None:
        while not self.done.wait(self.period):
            self.sent += 1
            problem = self.load()
            if problem:
                self.failed.append(problem)

    def load(self) -> str | None:
        """One page load; what went wrong, or None."""
        try:
            with self.opener.open(self.system.url, timeout=5) as page:
                page.read()
                return None if page.status == 200 else f"status {page.status}"
        except urllib.error.HTTPError as answer:
            return f"status {answer.code}"
        except OSError as exc:
            return f"{type(exc).__name__}: {exc}"


@dataclass
class Sample:
    """One odometry message as the robot's endpoint sent it, stamped on arrival (time.monotonic())."""

    at: float
    x: float
    y: float
    yaw: float
    vx: float
    wz: float

    def still(self) -> bool:
        return abs(self.vx) < REST_SPEED and abs(self.wz) < REST_SPEED


REST_SPEED = 1e-3  # m/s and rad/s: the odometry's twist (four decimals) reads zero
REST_DRIFT = 0.01  # m the pose may wander while "at rest"


class Odometry:
    """A robot's own odometry, read from its simulated endpoint as any rosbridge client reads it, in a thread.

    It follows the simulator through its restarts (connecting again until the endpoint answers), so what it
    shows is what the robot does, whatever the portal believes.
    """

    def __init__(self, url: str, topic: str = "/odom") -> None:
        self.url, self.topic = url, topic
        self.samples: deque[Sample] = deque(maxlen=4000)  # 20 Hz: over three minutes
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, name=f"odometry {url}", daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.done.set()
        self.thread.join(timeout=5)

    def _run(self) -> None:
        from websockets.exceptions import WebSocketException
        from websockets.sync.client import connect

        subscribe = {"op": "subscribe", "topic": self.topic, "type": "nav_msgs/Odometry"}
        while not self.done.is_set():
            try:
                with connect(self.url, open_timeout=2, close_timeout=1) as ws:
                    ws.send(json.dumps(subscribe))
                    while not self.done.is_set():
                        try:
                            raw = ws.recv(timeout=0.5)
                        except TimeoutError:
                            continue
                        self._take(json.loads(raw))
            except (OSError, WebSocketException, TimeoutError):
                self.done.wait(0.1)  # the simulator is down: try again

    def _take(self, frame: dict) -> None:
        if frame.get("op") != "publish" or frame.get("topic") != self.topic:
            return
        try:
            pose, twist = frame["msg"]["pose"]["pose"], frame["msg"]["twist"]["twist"]
            z, w = pose["orientation"]["z"], pose["orientation"]["w"]
            sample = Sample(
                time.monotonic(),
                float(pose["position"]["x"]),
                float(pose["position"]["y"]),
                2 * math.atan2(z, w),
                float(twist["linear"]["x"]),
                float(twist["angular"]["z"]),
            )
        except (KeyError, TypeError, ValueError):
            return  # not an odometry message (the garbage test puts some on the topic): not the robot's
        self.samples.append(sample)

    def latest(self, fresh: float = 0.5) -> Sample | None:
        """The last sample if it arrived within `fresh` s."""
        last = self.samples[-1] if self.samples else None
        return last if last is not None and time.monotonic() - last.at < fresh else None

    def moving(self) -> bool:
        last = self.latest()
        return last is not None and not last.still()

    def rested_since(self, hold: float = 1.0) -> float | None:
        """When the robot came to rest (monotonic), if it has been at rest for `hold` s up to now: every sample
        since shows a zero twist and a pose within REST_DRIFT of the first. None while it moves (or no odometry)."""
        last = self.latest()
        if last is None or not last.still():
            return None
        since = last
        for sample in reversed(self.samples):
            if not sample.still() or math.dist((sample.x, sample.y), (last.x, last.y)) > REST_DRIFT:
                break
            since = sample
        return since.at if last.at - since.at >= hold else None

    def travelled(self, after: float) -> float:
        """Metres driven (odometry) since the moment `after` (monotonic)."""
        points = [(sample.x, sample.y) for sample in self.samples if sample.at >= after]
        steps = [math.dist(a, b) for a, b in itertools.pairwise(points)]
        return sum(step for step in steps if step < 0.5)  # a longer one is a restarted simulator's new odom


def send_frames(url: str, frames: list, period: float = 0.05) -> int:
    """Send frames (text as is; anything else as JSON) to a rosbridge endpoint, one every `period` s, as one
    client; how many were sent."""
    from websockets.sync.client import connect

    with connect(url, open_timeout=5, close_timeout=1) as ws:
        for frame in frames:
            ws.send(frame if isinstance(frame, str | bytes) else json.dumps(frame))
            time.sleep(period)
    return len(frames)
