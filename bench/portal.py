"""A fresh, private portal for one benchmark run: temp var dir (SQLite, secret), embedded Redis, uvicorn, Celery.

Nothing is shared with a developer's `make run` or the test suite: every file lives in a temp directory that is
removed at the end, and Redis listens on a unix socket inside it.
"""

import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import django
from django.core.management import call_command
from django.test import Client

from fleet import embedded_redis, websocket
from simworker.testing import free_port

BASE_DIR = Path(__file__).resolve().parent.parent
BENCH_USER = "bench"


class Portal:
    """Set Django up on a temp database in this process; start the web and worker processes on demand."""

    def __init__(self) -> None:
        self.tmp = Path(tempfile.mkdtemp(prefix="fleetbench-"))
        self.socket = self.tmp / "redis.sock"
        self.port = free_port()
        self.redis = None
        self.procs: dict[str, subprocess.Popen] = {}
        self.env: dict[str, str] = {}
        self.user = None

    # ----- this process -----
    def setup(self) -> "Portal":
        """Start Redis, point Django at the temp dir, migrate, create the bench user."""
        redis_url = os.environ.get("BENCH_REDIS_URL")  # e.g. redis://127.0.0.1:6379/13, else a private one
        if not redis_url:
            self.redis = embedded_redis.start(self.socket)
            redis_url = f"unix://{self.socket}"
        self.env = {
            "FLEET_VAR_DIR": str(self.tmp),
            "REDIS_URL": redis_url,
            "DJANGO_SETTINGS_MODULE": "fleet.settings",
            "PYTHONUNBUFFERED": "1",
        }
        os.environ.pop("DATABASE_URL", None)  # always the temp SQLite: never a shared database
        os.environ.update(self.env)
        django.setup()
        call_command("migrate", "--noinput", verbosity=0)
        # Deferred: needs the app registry (bench modules are imported before django.setup()).
        from django.contrib.auth.models import User

        self.user = User.objects.create_superuser(BENCH_USER, password="bench-password-1")
        try:
            call_command("setup_demo", verbosity=0)  # the demo map and its locations A..I
        except Exception as exc:  # the bench still runs what needs no locations
            print(f"[bench] setup_demo failed: {exc}", flush=True)
        return self

    def session_cookie(self) -> str:
        """A logged-in session for the bench user, as a browser would hold it."""
        client = Client()
        client.force_login(self.user)
        return client.cookies["sessionid"].value

    # ----- other processes -----
    @property
    def http_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def start_web(self, timeout: float = 30.0) -> None:
        """uvicorn serving the ASGI app (HTTP API and Channels WebSockets)."""
        if "web" in self.procs:
            return
        cmd = [
            sys.executable,
            "-m",
            "uvicorn",
            "fleet.asgi:application",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--log-level",
            "warning",
            "--no-access-log",
            *websocket.OPTION,
        ]
        self._spawn("web", cmd)
        deadline = time.time() + timeout
        while time.time() < deadline:
            try:
                urllib.request.urlopen(f"{self.http_url}/login/", timeout=1)
                return
            except OSError:
                self._check_alive("web")
                time.sleep(0.2)
        raise RuntimeError(f"portal web server did not answer within {timeout:g} s (log: {self.tmp}/web.log)")

    def start_worker(self) -> None:
        """The workers as `make run` has them: the executor (the robots' instructions, `manage.py executor`), the
        Celery instructions worker (recordings, experiment runs) and a separate control worker, so stops and
        registrations never wait behind anything."""
        if "worker" in self.procs:
            return
        common = ["-l", "warning", "--without-gossip", "--without-mingle", "--without-heartbeat"]
        celery = [sys.executable, "-m", "celery", "-A", "fleet", "worker"]
        self._spawn("executor", [sys.executable, "manage.py", "executor"])
        self._spawn(
            "worker",
            [*celery, "-n", "instructions@%h", "-Q", "instructions", "-P", "threads", "-c", "8", *common],
        )
        self._spawn(
            "control", [*celery, "-n", "control@%h", "-Q", "control,registration", "-c", "1", *common]
        )
        time.sleep(2.0)
        for name in ("executor", "worker", "control"):
            self._check_alive(name)

    def start_links(self) -> None:
        """The robot links as `make run` has them: one rosbridge link per registered endpoint, live poses."""
        if "links" in self.procs:
            return
        self._spawn("links", [sys.executable, "manage.py", "robotlinks"])
        time.sleep(1.0)
        self._check_alive("links")

    def start_scheduler(self) -> None:
        """The scheduler as `make run` has it: the watchdog of lost executors, time slots, sweeps."""
        if "scheduler" in self.procs:
            return
        self._spawn("scheduler", [sys.executable, "manage.py", "scheduler"])
        time.sleep(1.0)
        self._check_alive("scheduler")

    def _spawn(self, name: str, cmd: list[str]) -> None:
        log = open(self.tmp / f"{name}.log", "wb")  # noqa: SIM115 - lives as long as the process
        self.procs[name] = subprocess.Popen(
            cmd, cwd=BASE_DIR, env={**os.environ, **self.env}, stdout=log, stderr=subprocess.STDOUT
        )

    def _check_alive(self, name: str) -> None:
        proc = self.procs[name]
        if proc.poll() is not None:
            tail = (self.tmp / f"{name}.log").read_text(errors="replace")[-1500:]
            raise RuntimeError(f"portal {name} exited with {proc.returncode}:\n{tail}")

    def log_tail(self, name: str, chars: int = 1500) -> str:
        path = self.tmp / f"{name}.log"
        return path.read_text(errors="replace")[-chars:] if path.exists() else ""

    def close(self, keep: bool = False) -> None:
        """Stop the processes this portal started (by their ids), Redis, and remove the temp dir (unless kept)."""
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.terminate()
        for proc in self.procs.values():
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
        if self.redis is not None:
            embedded_redis.stop(self.redis, self.socket)
        if keep:
            print(f"[bench] kept {self.tmp} (web.log, worker.log)", flush=True)
        else:
            shutil.rmtree(self.tmp, ignore_errors=True)
