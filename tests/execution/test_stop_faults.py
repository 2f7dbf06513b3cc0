"""A person's stop gets its zero out whatever Redis, the database, another robot's endpoint or the workers do.

For each fault (a Redis of the test's own frozen, or refusing writes; the database locked by another writer; a
robot endpoint flooding its link; the instructions worker hung), each stop path (a "stop" typed in the console over
the page's socket, the STOP ALL form, the API's POST /api/instructions "stop") is taken while two simulated robots
drive: both must come to rest (the simulator's own bodies) and the answer carries no 5xx.

The CLI's stop (`manage.py instruct "stop"`, a fresh process) is taken with the portal's links process running
(`manage.py robotlinks`): its zeros go through that process's stop socket, on links already up.
"""

from __future__ import annotations

import asyncio
import copy
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from asgiref.sync import sync_to_async
from channels.testing import WebsocketCommunicator
from django.db import connection

from execution import dispatch, fast_stop
from execution.models import Execution
from fleet import processes
from fleet.env import channels_host
from robots import stopsocket
from robots.commands import CommandSurface
from robots.models import Robot
from robots.rosbridge import pool, sync
from simworker.testing import running_world
from tests.execution.conftest import register
from tests.execution.faults import DatabaseLock, DedicatedRedis, Flooder
from tests.execution.helpers import at_rest, parse, step, wait_for, without_command_timeout

pytestmark = [pytest.mark.timeout(90), pytest.mark.usefixtures("seeded_ontology")]

ROBOTS = ("turtlebot", "husky")


@pytest.fixture
def own_redis(settings):
    """A Redis of this test's own, which every Redis user of the process (flags, cache, channel layer) goes to."""
    server = DedicatedRedis()
    settings.REDIS_URL = server.url
    settings.CACHES = {"default": {**settings.CACHES["default"], "LOCATION": server.url}}
    layers = copy.deepcopy(settings.CHANNEL_LAYERS)
    layers["default"]["CONFIG"]["hosts"] = [channels_host(server.url)]
    settings.CHANNEL_LAYERS = layers
    yield server
    server.close()


@pytest.fixture
def stop_world(own_redis, exec_settings, transactional_db, fleet_admin, client):
    """Turtlebot and husky registered, keeping their last command (a robot at rest is the portal's doing); no
    executor runs (the robots are driven straight on their links)."""
    with running_world("paper", endpoints=list(ROBOTS)) as sim:
        sim.robots = register(sim, list(ROBOTS))
        for name in ROBOTS:
            without_command_timeout(sim, name)
        fast_stop.TARGETS.load_now()
        client.force_login(fleet_admin)
        sim.client = client
        yield sim
        fast_stop.TARGETS.by_robot = {}


def drive(sim) -> None:
    """Set both robots moving, straight on their own links (as a running instruction would)."""
    for robot in Robot.objects.filter(name__in=ROBOTS).prefetch_related("bindings"):
        sync.get_client(robot.endpoint).publish(*CommandSurface.of(robot).velocity(0.3, 0.5, 0.0))
    wait_for(lambda: not any(at_rest(sim, name) for name in ROBOTS), 10, "both robots moving")


# ----- the three stop paths: each applies the fault at the last moment; (when it asked, seconds to the answer,
# status, words) -----


def typed_stop(sim, fault) -> tuple[float, float, int, str]:
    """ "stop" typed in the console, sent over the dashboard's socket (connected before the fault)."""
    from fleet.asgi import application

    cookie = f"sessionid={sim.client.cookies['sessionid'].value}".encode()

    async def run():
        headers = [(b"origin", b"http://127.0.0.1"), (b"cookie", cookie)]
        socket = WebsocketCommunicator(application, "/ws/fleet/", headers=headers)
        connected, _ = await socket.connect(timeout=20)
        assert connected
        await socket.receive_json_from(timeout=20)  # the snapshot
        await fast_stop.TARGETS._load()  # what connect started in the background (the links), done now
        await sync_to_async(fault.apply)()
        started = time.monotonic()
        await socket.send_json_to({"command": "instruct", "text": "stop", "ref": "typed"})
        reply = {}
        while reply.get("type") != "command.result":
            reply = await socket.receive_json_from(timeout=20)
        answered = time.monotonic() - started
        await socket.disconnect(timeout=5)
        return (
            started,
            answered,
            (200 if reply["ok"] else 400),
            reply.get("instruction", {}).get("outcome") or reply["detail"],
        )

    return asyncio.run(run())


def stop_all_form(sim, fault) -> tuple[float, float, int, str]:
    """The STOP ALL form (robots=all), answered in JSON to read its words."""
    fault.apply()
    started = time.monotonic()
    answer = sim.client.post("/control/stop/", {"robots": "all"}, HTTP_ACCEPT="application/json")
    return started, time.monotonic() - started, answer.status_code, answer.json().get("detail", "")


def api_stop(sim, fault) -> tuple[float, float, int, str]:
    """POST /api/instructions {"text": "stop"}, as the console does without its socket."""
    fault.apply()
    started = time.monotonic()
    answer = sim.client.post("/api/instructions", {"text": "stop"}, content_type="application/json")
    body = answer.json()
    return (
        started,
        time.monotonic() - started,
        answer.status_code,
        body.get("outcome") or body.get("detail", ""),
    )


PATHS = [typed_stop, stop_all_form, api_stop]


# ----- the faults -----


class Fault:
    """apply() at the moment of the stop, release() after it."""

    def apply(self) -> None: ...

    def release(self) -> None: ...

    def check(self, answer: str) -> None:
        """What else must hold after the stop (its answer's words), beyond the robots at rest."""

    def close(self) -> None:
        """Once the test is done."""


class RedisFrozen(Fault):
    def __init__(self, server: DedicatedRedis) -> None:
        self.server = server

    def apply(self) -> None:
        self.server.freeze()

    def release(self) -> None:
        self.server.thaw()


class RedisRefusing(RedisFrozen):
    def apply(self) -> None:
        self.server.refuse_writes()

    def release(self) -> None:
        self.server.accept_writes()


class DatabaseLocked(Fault):
    def __init__(self) -> None:
        self.lock = DatabaseLock(connection.settings_dict)

    def apply(self) -> None:
        self.lock.take()

    def release(self) -> None:
        self.lock.release()

    def check(self, answer: str) -> None:
        assert "the database is locked" in answer, answer  # the lock held the stop's writes off, and is said

    def close(self) -> None:
        self.lock.close()  # its connection ended: the test database can be flushed and dropped


class Flooding(Fault):
    """A third robot whose endpoint floods: its link is up in this process before the stop, as in operation."""

    def __init__(self, flooder: Flooder) -> None:
        self.flooder = flooder
        flood = Robot.objects.create(name="flood", endpoint=flooder.url, link_status=Robot.Link.ONLINE)
        flood.bindings.create(action="move", target="/cmd_vel", message_type="geometry_msgs/Twist")
        fast_stop.TARGETS.load_now()
        self.link = sync.get_client(flooder.url, connect_timeout=10)

    def check(self, answer: str) -> None:
        inflow = self.link.client.inflow  # it did flood (what exceeded the rate, if any, was dropped unread)
        assert inflow.taken + inflow.dropped > 1000


class HungWorker(Fault):
    """The instructions worker takes nothing: an instruction for turtlebot stays queued until the stop."""

    def __init__(self, monkeypatch, user) -> None:
        monkeypatch.setattr(dispatch.executor, "wake", lambda robot_ids: None)
        self.user = user

    def apply(self) -> None:
        from execution.instructions import submit

        submit("move turtlebot", self.user, parse=parse(step(["turtlebot"], 1.0, 1.0)))
        assert Execution.objects.filter(status=Execution.Status.QUEUED).exists()

    def check(self, answer: str) -> None:
        assert not Execution.objects.filter(status=Execution.Status.QUEUED).exists()  # cancelled by the stop


@pytest.fixture
def fault(request, stop_world, own_redis, monkeypatch, fleet_admin):
    kind = request.param
    if kind == "flooding endpoint":
        flooder = Flooder()
        flooding = Flooding(flooder)
        flooding.name = kind
        yield flooding
        flooder.close()
        return
    made = {
        "none": Fault,
        "redis frozen": lambda: RedisFrozen(own_redis),
        "redis refusing writes": lambda: RedisRefusing(own_redis),
        "database locked": DatabaseLocked,
        "hung worker": lambda: HungWorker(monkeypatch, fleet_admin),
    }[kind]()
    made.name = kind
    yield made
    made.release()
    made.close()


FAULTS = ["redis frozen", "redis refusing writes", "database locked", "flooding endpoint", "hung worker"]
OUT = os.environ.get("FLEET_STOP_FAULTS_OUT")  # bench.stop_faults: where the figures go, and how many rounds
ROUNDS = int(os.environ.get("FLEET_STOP_FAULTS_ROUNDS", "1"))
FIGURES: list[dict] = []


class ZeroWatch:
    """When every robot's body first holds a zero command (the simulator's own state, polled every ~5 ms)."""

    def __init__(self, sim) -> None:
        self.sim, self.at = sim, None
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, name="zero watch", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        bodies = [self.sim.fleet.robots[name].body for name in ROBOTS]
        zero = lambda: all((body.cmd.vx, body.cmd.wz) == (0.0, 0.0) for body in bodies)  # noqa: E731
        while not self.done.is_set() and self.at is None:
            if self.sim.call(zero):
                self.at = time.monotonic()
            self.done.wait(0.005)

    def close(self) -> None:
        self.done.set()
        self.thread.join(5)


@pytest.fixture(scope="module", autouse=True)
def figures():
    """The rows of a bench run (bench/stop_faults.py), written when the module ends."""
    yield FIGURES
    if OUT and FIGURES:
        Path(OUT).write_text(json.dumps(FIGURES, indent=1) + "\n")


@pytest.mark.parametrize("fault", FAULTS + (["none"] if OUT else []), indirect=True)
def test_every_stop_path_zeroes_every_moving_robot(fault, stop_world):
    for path in PATHS * ROUNDS:
        drive(stop_world)
        watch = ZeroWatch(stop_world)
        try:
            started, answered, status, answer = path(stop_world, fault)
            wait_for(lambda: all(at_rest(stop_world, n) for n in ROBOTS), 10, f"{path.__name__}: at rest")
            wait_for(lambda w=watch: w.at is not None, 5, "the zero seen")
        finally:
            fault.release()
            watch.close()
        assert status < 500 and "stopped" in answer.lower(), (path.__name__, status, answer)
        fault.check(answer)
        FIGURES.append(
            {
                "fault": fault.name,
                "path": path.__name__,
                "zero_ms": round((watch.at - started) * 1000, 1),
                "answer_ms": round(answered * 1000, 1),
                "status": status,
                "answer": answer,
            }
        )


@pytest.fixture
def links_process(exec_settings, transactional_db, fleet_admin):
    """Turtlebot and husky registered and driving-ready, and `manage.py robotlinks` running on a var folder of its
    own (its stop socket there), sharing the test's database and Redis: the portal as far as a CLI stop sees it."""
    with running_world("paper", endpoints=list(ROBOTS)) as sim:
        register(sim, list(ROBOTS))
        for name in ROBOTS:
            without_command_timeout(sim, name)
        try:
            env = processes.fleet_env() | {"FLEET_VAR_DIR": tempfile.mkdtemp(prefix="fleet-cli-")}
        except ValueError as exc:  # an in-memory test database
            pytest.skip(f"a links process cannot share the test database: {exc}")
        sim.env, sim.socket = env, Path(env["FLEET_VAR_DIR"]) / "proc" / "stop.sock"
        proc = processes.start([sys.executable, "manage.py", "robotlinks"], env)
        try:
            wait_for(
                lambda: linked(sim.socket), 60, "the links process's stop socket, with both robots' links up"
            )
            yield sim
        finally:
            processes.end(proc)


def linked(where: Path) -> bool:
    """The links process answers on its stop socket, with both robots' links up."""
    return set(ROBOTS) <= set((stopsocket.ask({"status": True}, where) or {}).get("up", []))


def cli_stop(sim, user) -> tuple[float, float, float, str]:
    """`manage.py instruct --user NAME -v 2 "stop"` in a process of its own: (when it asked the portal, when the
    process started, when it ended, its output)."""
    command = [sys.executable, "manage.py", "instruct", "--user", user.username, "-v", "2", "stop"]
    spawned = time.monotonic()
    done = subprocess.run(
        command, env=sim.env, cwd=processes.BASE_DIR, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    asked = re.search(r"portal stop asked at monotonic ([0-9.]+)", done.stdout)
    assert asked, done.stdout  # the stop went through the portal's stop socket
    return float(asked.group(1)), spawned, time.monotonic(), done.stdout


def test_the_cli_stop_zeroes_every_moving_robot_through_the_links_process(links_process, fleet_admin):
    """The CLI's zeros leave from the links process's links (its stop socket counts them), every moving robot
    comes to rest and stays there (odometry), and the instruction says they stopped."""
    sim = links_process
    for _ in range(ROUNDS):
        served = stopsocket.ask({"status": True}, sim.socket)["served"]
        drive(sim)
        watch = ZeroWatch(sim)
        try:
            asked, spawned, ended, out = cli_stop(sim, fleet_admin)
            wait_for(lambda: all(at_rest(sim, n) for n in ROBOTS), 10, "the robots at rest")
            wait_for(lambda w=watch: w.at is not None, 5, "the zero seen")
        finally:
            watch.close()
        assert re.search(r"zeros sent by the portal's links in \d+ ms: husky, turtlebot", out), out
        assert "instruction #" in out and ": succeeded" in out, out
        assert stopsocket.ask({"status": True}, sim.socket)["served"] > served
        parked = {name: sim.pose(name) for name in ROBOTS}
        time.sleep(0.5)
        assert all(math.dist(sim.pose(n)[:2], parked[n][:2]) < 0.01 for n in ROBOTS)  # and they stay at rest
        FIGURES.append(
            {
                "fault": "none",
                "path": "cli_stop",
                "zero_ms": round((watch.at - asked) * 1000, 1),  # from its request, as for the other paths
                "answer_ms": round((ended - asked) * 1000, 1),  # the command's end: after its bookkeeping
                "start_zero_ms": round(
                    (watch.at - spawned) * 1000, 1
                ),  # from the process's start (Python, Django)
                "status": 0,
                "answer": out.strip().splitlines()[-1],
            }
        )


def test_a_page_loop_whose_links_are_not_up_yet_gets_its_zeros_from_the_links_process(
    links_process, settings
):
    """A fresh web process's first stop: its own loop has no link up yet (a zero there would wait for one), so
    the robots it missed are asked of the portal's links process, whose links are up; both robots come to rest
    from that alone (no instruction runs to see the flags) and the links process counts the stop."""
    sim = links_process
    settings.FLEET_STOP_SOCKET = sim.socket
    fast_stop.TARGETS.load_now()
    served = stopsocket.ask({"status": True}, sim.socket)["served"]
    drive(sim)

    async def first_stop() -> int:
        sent = await fast_stop.stop_now(fast_stop.TARGETS.ids("all"))  # connect_timeout 0: a page's loop
        await asyncio.gather(
            *fast_stop._ASKING
        )  # the web process's loop lives on; this one waits for the ask
        await pool.close_all()
        return sent

    try:
        assert asyncio.run(first_stop()) == 0  # no zero from this loop: its links were still connecting
        wait_for(lambda: all(at_rest(sim, n) for n in ROBOTS), 10, "the robots at rest")
    finally:
        fast_stop.TARGETS.by_robot = {}
    assert stopsocket.ask({"status": True}, sim.socket)["served"] == served + 1
