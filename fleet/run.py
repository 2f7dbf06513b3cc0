"""`make run`: migrate, set up the demo, then run every process of the system under supervisord.

A process that dies is started again (fleet/supervision.py says how); its output and supervisord's one line about
its death reach the terminal with its name in front. One Ctrl-C stops everything and `make run` exits 0.

    FLEET_PORT           the portal's port (8000)
    FLEET_SIM_PORT_BASE  the simulated endpoints' first port (9090; the demo world uses seven from there)
    FLEET_VAR_DIR        the database, Redis's data, the logs (var/log/) and the supervisor's files (var/)
    REDIS_URL            a Redis to use; unset, an embedded one is run (and restarted) under var/
    FLEET_EXECUTORS      how many executor processes run the robots' instructions (1; execution/executor.py)
    FLEET_SIM_OPTIONS    more options for the simulator (e.g. `--keep-last-command`, as the chaos tests run it)

`supervisorctl -c var/supervisord.conf status` shows the processes while it runs.
"""

from __future__ import annotations

import http.client
import os
import shlex
import signal
import subprocess
import sys
import threading
import time
import urllib.request
import xmlrpc.client
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import redis
from redis.backoff import NoBackoff
from redis.retry import Retry

from fleet import hangwatch, runguard, websocket
from fleet.supervision import (
    Bounds,
    Layout,
    LogRelay,
    Program,
    render_config,
    rpc,
    start_supervisord,
    wait_for_rpc,
)
from fleetcore.world import load_world

BASE_DIR = Path(__file__).resolve().parent.parent
HOST = "127.0.0.1"


@dataclass(frozen=True)
class Setup:
    """What this `make run` runs where, from the environment."""

    port: int
    sim_port_base: int
    var_dir: Path
    world: str
    redis_url: str | None  # None: the embedded Redis
    sim_options: tuple[str, ...] = ()
    executors: int = 1  # executor processes: executor-1 .. executor-N

    @classmethod
    def from_env(cls, environ=os.environ) -> Setup:
        return cls(
            port=int(environ.get("FLEET_PORT", "8000")),
            sim_port_base=int(environ.get("FLEET_SIM_PORT_BASE", "9090")),
            var_dir=Path(environ.get("FLEET_VAR_DIR", BASE_DIR / "var")).resolve(),
            world=environ.get("FLEET_WORLD", "paper"),
            redis_url=environ.get("REDIS_URL") or None,
            sim_options=tuple(shlex.split(environ.get("FLEET_SIM_OPTIONS", ""))),
            executors=int(environ.get("FLEET_EXECUTORS", "1")),
        )

    @property
    def redis_socket(self) -> Path:
        return self.var_dir / "redis.sock"

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}/"

    def needs(self) -> runguard.Needs:
        """What this run holds: the var folder, the portal's and the simulator's ports, the Redis socket."""
        offsets = [endpoint.port_offset for endpoint in load_world(self.world).endpoints]
        ports = (self.port, *(self.sim_port_base + offset for offset in offsets))
        return runguard.Needs(self.var_dir, ports, None if self.redis_url else self.redis_socket)

    def env(self) -> dict[str, str]:
        """Every process's environment: ours, with the Redis they share and unbuffered output."""
        redis_url = self.redis_url or f"unix://{self.redis_socket}"
        return {
            **os.environ,
            "REDIS_URL": redis_url,
            "FLEET_VAR_DIR": str(self.var_dir),
            runguard.RUN_ENV: str(self.var_dir),  # marks every process of this run (fleet/runguard.py)
            "PYTHONUNBUFFERED": "1",
        }


# Heartbeat bounds (fleet/hangwatch.py): an alert past the first, a restart past the second. The links process is
# alerted on within 2 s of hanging (issue 31: a frozen fleet must not look live), and so is an executor, whose loop
# sends the robots' commands and leaves every query to a thread; the scheduler's pass and a worker's beat (from a
# thread) get more room: a busy database may rightly hold a pass for seconds.
QUICK, ROOMY = Bounds(alert_s=1.0, restart_s=5.0), Bounds(alert_s=3.0, restart_s=15.0)
HANGWATCH = Bounds(alert_s=10.0, restart_s=10.0)  # watched by `make run` itself: no alert, only a restart


def programs(setup: Setup, python: str = sys.executable) -> list[Program]:
    """The system's processes; the embedded Redis first (started with the supervisor, stopped last). Redis, the
    scheduler and the links process are single (one per var folder, always: a lock each); the rest beat. The
    robots are spread over setup.executors executor processes (execution/executor.py)."""
    manage = [python, "manage.py"]
    celery = [python, "-m", "celery", "-A", "fleet", "-q", "worker", "-l", "warning"]
    sim_ports = ["--port-base", str(setup.sim_port_base)]
    web_options = ["--host", HOST, "--port", str(setup.port), "--log-level", "warning"]
    web_options += ["--timeout-graceful-shutdown", "5", "--no-proxy-headers"]  # portal/clientaddr.py decides
    web_options += websocket.OPTION  # its compression at level 1 (fleet/websocket.py)
    listed = [
        Program("web", [python, "-m", "uvicorn", "fleet.asgi:application", *web_options], hung=QUICK),
        # The default queue (still named instructions) carries recordings and experiment runs, which wait most
        # of their time: a few threads. Stops and registrations have a worker of their own.
        Program(
            "worker",
            [*celery, "-n", "instructions@%h", "-Q", "instructions", "-P", "threads", "-c", "8"],
            hung=ROOMY,
        ),
        Program(
            "control", [*celery, "-n", "control@%h", "-Q", "control,registration", "-c", "1"], hung=ROOMY
        ),
        Program(
            "sim", [*manage, "simworker", "--world", setup.world, *sim_ports, *setup.sim_options], hung=QUICK
        ),
        Program(
            "links",
            [*manage, "robotlinks", "--register-world", setup.world, *sim_ports],
            single=True,
            hung=QUICK,
        ),
        # time slots, lost workers, stalled robot queues (issue 6)
        Program("scheduler", [*manage, "scheduler"], single=True, hung=ROOMY),
        # the robots' instructions: one asyncio task per robot, each robot run by one of them (issue 34)
        *(Program(f"executor-{n}", [*manage, "executor"], hung=QUICK) for n in range(1, setup.executors + 1)),
    ]
    watched = [f"{program.name}:{program.hung.alert_s:g}:{program.hung.restart_s:g}" for program in listed]
    # restarts a hung process; it beats too, and `make run` itself restarts it if it hangs (wait_watching)
    hangwatch = [python, "-m", "fleet.hangwatch", "--var-dir", str(setup.var_dir), *watched]
    listed.append(Program("hangwatch", hangwatch, single=True, hung=HANGWATCH))
    if setup.redis_url is None:
        serve = [python, "-m", "fleet.embedded_redis", "serve", "--socket", str(setup.redis_socket)]
        listed.insert(0, Program("redis", serve, autostart=True, priority=10, group=None, single=True))
    return listed


def main() -> int:
    setup = Setup.from_env()
    with foreground_terminal():
        return run(setup)


def run(setup: Setup) -> int:
    """Start the supervisor, bring the system up under it; return once the supervisor has stopped."""
    layout = Layout(setup.var_dir)
    try:  # one run per var folder: nothing of an earlier one left, nothing else on our ports
        lock = runguard.guard(setup.needs(), layout.run_lock, say=lambda line: print(line, flush=True))
    except runguard.Refused as refused:
        print(f"make run: {refused}", flush=True)
        return 1
    listed = programs(setup)
    layout.log_dir.mkdir(parents=True, exist_ok=True)
    layout.config.write_text(render_config(listed, layout, BASE_DIR))
    # made before anything runs: what the logs held already is not repeated
    relay = LogRelay(layout, [program.name for program in listed])
    supervisord = start_supervisord(layout, setup.env(), keep_fds=(lock,))
    os.close(lock)  # supervisord holds it now, for as long as it lives
    stopping = stop_on_signals(supervisord)
    relay.start()
    try:
        return bring_up(setup, layout, supervisord, stopping)
    finally:
        stop(supervisord)
        relay.stop()


def bring_up(setup: Setup, layout: Layout, supervisord: subprocess.Popen, stopping: threading.Event) -> int:
    """Wait for the supervisor (and the embedded Redis), prepare the database, start the rest, say where to go;
    then wait for the supervisor to end. 0 when we were asked to stop."""
    proxy = wait_for_rpc(layout, supervisord)
    if proxy is None:
        print(f"make run: the supervisor did not start (is another `make run` using {setup.var_dir}?)")
        return supervisord.poll() or 1
    if setup.redis_url is None and not wait_for_redis(setup.redis_socket, supervisord):
        print(f"make run: the embedded Redis did not answer on {setup.redis_socket}: see its lines above")
        return 0 if stopping.is_set() else 1
    login = prepare(setup.env(), stopping)
    if login is None:
        return 0 if stopping.is_set() else 1
    proxy.supervisor.startAllProcesses(False)
    print(f"\n  Fleet portal: {setup.url}  (starting; Ctrl-C stops everything)\n", flush=True)
    threading.Thread(target=say_when_ready, args=(setup.url, login), name="announcement", daemon=True).start()
    code = wait_watching(layout, supervisord)
    if not stopping.is_set() and code < 0:  # killed: its processes died with it (fleet/procwrap.py)
        print(
            f"make run: the supervisor was killed ({signal.Signals(-code).name}); every process went with it"
        )
    return 0 if stopping.is_set() else code or 1


def wait_watching(layout: Layout, supervisord: subprocess.Popen, period: float = 1.0) -> int:
    """Wait for the supervisor to end; meanwhile restart the hang watcher if it stops beating (it watches the
    others, and we watch it: nothing watches us but the person at the terminal)."""
    while supervisord.poll() is None:
        try:
            supervisord.wait(timeout=period)
        except subprocess.TimeoutExpired:
            restart_if_hung(layout, "hangwatch", HANGWATCH)
    return supervisord.returncode


def restart_if_hung(layout: Layout, name: str, bounds: Bounds) -> None:
    """Kill the process if it has not beaten within its bound (the supervisor starts it again)."""
    try:
        info = rpc(layout).supervisor.getProcessInfo(f"fleet:{name}")
    except (OSError, http.client.HTTPException, xmlrpc.client.Error):
        return  # the supervisor is busy or stopping: asked again next time
    quiet = hangwatch.silence(info, layout.beat(name), time.time())
    if quiet is not None and hangwatch.verdict(quiet, bounds) == "restart":
        hangwatch.kill(quiet.pid, f"make run: {name} hung (no heartbeat for {quiet.seconds:.1f} s)")


def wait_for_redis(socket_path: Path, supervisord: subprocess.Popen, timeout: float = 30.0) -> bool:
    """Whether the embedded Redis answers a PING within timeout (it replays its append-only file first)."""
    client = redis.Redis(unix_socket_path=str(socket_path), socket_timeout=1, retry=Retry(NoBackoff(), 0))
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and supervisord.poll() is None:
        try:
            if client.ping():
                print(f"embedded Redis at unix://{socket_path} (its data kept there too)", flush=True)
                return True
        except redis.RedisError:
            time.sleep(0.1)  # not listening yet, or still loading its data
    return False


def prepare(env: dict[str, str], stopping: threading.Event) -> str | None:
    """Migrate and set up the demo; the login line it says, or None if either failed or we are stopping."""
    python = sys.executable
    migrate = subprocess.run([python, "manage.py", "migrate", "--noinput", "-v", "0"], cwd=BASE_DIR, env=env)
    if migrate.returncode or stopping.is_set():
        return None
    # its output is kept to say the login again later; its errors go straight to the terminal
    demo = subprocess.run(
        [python, "manage.py", "setup_demo"], cwd=BASE_DIR, env=env, stdout=subprocess.PIPE, text=True
    )
    print(demo.stdout, end="", flush=True)
    if demo.returncode or stopping.is_set():
        return None
    return next((line for line in demo.stdout.splitlines() if line.startswith("login:")), "")


def stop_on_signals(supervisord: subprocess.Popen) -> threading.Event:
    """Ctrl-C, SIGTERM or a closed terminal: we tell supervisord, which stops every process (Redis last) and then
    itself."""
    stopping = threading.Event()

    def _stop(*_args):
        stopping.set()
        if supervisord.poll() is None:
            supervisord.send_signal(signal.SIGTERM)

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _stop)
    return stopping


def stop(supervisord: subprocess.Popen, timeout: float = 60.0) -> None:
    """Ask supervisord to stop (if it has not) and wait for it; it waits for each process in turn."""
    if supervisord.poll() is None:
        supervisord.send_signal(signal.SIGTERM)
    try:
        supervisord.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        supervisord.kill()
        supervisord.wait()


@contextmanager
def foreground_terminal() -> Iterator[None]:
    """Hold the terminal's foreground in a process group of our own, so that Ctrl-C reaches us but not make.

    make answers SIGINT by killing itself with it once its child has ended, whatever the child's status: `make
    run` would end with status 130 however cleanly everything stopped. With our own foreground group, make never
    sees the Ctrl-C and exits with ours. Ctrl-Z is ignored meanwhile: it would stop us alone, with make still in
    the shell's foreground, and leave the terminal hanging. Without a terminal (a test, CI) nothing changes.
    """
    fd = sys.stdin.fileno() if sys.stdin and sys.stdin.isatty() else None
    if fd is None or os.tcgetpgrp(fd) != os.getpgrp():
        yield
        return
    previous = os.getpgrp()
    os.setpgid(0, 0)
    _set_foreground(fd, os.getpgrp())
    suspend = signal.signal(signal.SIGTSTP, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGTSTP, suspend)
        _set_foreground(fd, previous)


def _set_foreground(fd: int, group: int) -> None:
    """tcsetpgrp from a background group, which would otherwise stop us with SIGTTOU."""
    previous = signal.signal(signal.SIGTTOU, signal.SIG_IGN)
    try:
        os.tcsetpgrp(fd, group)
    except OSError:
        pass  # the terminal went away
    finally:
        signal.signal(signal.SIGTTOU, previous)


def say_when_ready(url: str, login: str) -> None:
    print(announcement(url, login), flush=True)


def announcement(url: str, login: str, timeout: float = 60.0) -> str:
    """Once the portal answers (or it has not within timeout): where to go and how to log in, said last."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"{url}login/", timeout=2) as response:
                if response.status == 200:
                    return f"\n  Fleet portal ready: {url}\n  {login}\n  Ctrl-C stops everything.\n"
        except OSError:
            pass  # not listening yet
        time.sleep(0.5)
    return f"\n  The portal did not answer at {url} within {timeout:.0f} s: see the web lines above.\n"


if __name__ == "__main__":
    sys.exit(main())
