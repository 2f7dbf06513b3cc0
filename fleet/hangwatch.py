"""`make run`'s hang watcher: a process that stops beating is alerted on, then killed for the supervisor to restart.

    python -m fleet.hangwatch --var-dir var links:1:5 web:1:5 scheduler:3:15 ...

Each watched process renews var/proc/<name>.beat from its main loop (fleetcore/heartbeat.py); the supervisor
only knows whether a process exists, this knows whether it works. Every POLL_S it reads the supervisor's process
list (XML-RPC, what supervisorctl uses) and each file's age: past the first bound a process_hung alert ("links
process hung (no heartbeat for 1.2 s)"), past the second SIGKILL to its process group (a stopped process cannot
act on SIGTERM); the supervisor starts it again, and the alert is resolved once every process beats again.
A process not yet beating since its start has STARTUP_S (Django loads for seconds on a busy machine).

It cannot hang anything else: nothing waits for it; the supervisor's answers have a timeout; the alerts (which
need the database) are sent by a thread of their own through a bounded queue, so a locked database delays an
alert, never a restart. It beats too, and `make run` restarts it if it stops (fleet/run.py, wait_watching).
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import os
import queue
import signal
import socket
import sys
import threading
import time
import xmlrpc.client
from dataclasses import dataclass, field
from pathlib import Path

import django
from django.db import close_old_connections

import alerts
from fleet.supervision import Bounds, Layout, rpc
from fleetcore.heartbeat import Heartbeat

POLL_S = 0.2
STARTUP_S = 60.0  # from a start to the first heartbeat
SETTLE_S = 20.0  # after a start, a silence is not alerted on (only restarted past its bound)
RPC_TIMEOUT_S = 2.0
KIND = "process_hung"  # alerts.models.Alert.Kind.PROCESS_HUNG


@dataclass(frozen=True)
class Silence:
    """How long one running process has gone without a heartbeat."""

    name: str
    pid: int
    seconds: float
    beaten: bool  # it has beaten since its start (else: seconds since the start)
    uptime: float = 0.0  # seconds since its start


def silence(info: dict, beat: Path, now: float) -> Silence | None:
    """A RUNNING process's silence (None for any other state); its wrapper removes the file at each start."""
    if info["statename"] != "RUNNING":
        return None
    uptime = max(0.0, now - info["start"])
    try:
        last = beat.stat().st_mtime
    except FileNotFoundError:
        return Silence(info["name"], info["pid"], uptime, beaten=False, uptime=uptime)
    return Silence(info["name"], info["pid"], max(0.0, now - last), beaten=True, uptime=uptime)


def verdict(quiet: Silence, bounds: Bounds) -> str:
    """ "ok", "alert" or "restart"."""
    if not quiet.beaten:
        return "restart" if quiet.seconds > STARTUP_S else "ok"
    if quiet.seconds > bounds.restart_s:
        return "restart"
    return "alert" if quiet.seconds > bounds.alert_s else "ok"


def kill(pid: int, why: str, say=print) -> None:
    """SIGKILL the process's group (the supervisor makes each process a group leader), saying why."""
    say(f"{why}: killed pid {pid}; the supervisor starts it again", flush=True)
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


class Alerts:
    """Raises and resolves the process_hung alert from a thread of its own (it needs Django and the database)."""

    def __init__(self) -> None:
        self.queue: queue.Queue = queue.Queue(maxsize=32)
        self.thread = threading.Thread(target=self._run, name="alerts", daemon=True)

    def start(self) -> Alerts:
        self.thread.start()
        return self

    def send(self, action: str, text: str) -> None:
        try:
            self.queue.put_nowait((action, text))
        except queue.Full:
            print(f"alert not sent (the database is behind): {text}", flush=True)

    def _run(self) -> None:
        os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")
        django.setup()
        while True:
            action, text = self.queue.get()
            close_old_connections()
            if action == "raise":
                alerts.raise_alert(KIND, None, text)
            else:
                alerts.resolve_alert(KIND, None, text)


@dataclass
class Watcher:
    """What it has seen: the processes hung now (their silence when first seen), the pids it killed."""

    layout: Layout
    bounds: dict[str, Bounds]
    alerts: Alerts
    say: object = print
    hung: dict[str, float] = field(default_factory=dict)
    killed: set[int] = field(default_factory=set)

    def check(self, infos: list[dict], now: float) -> None:
        before = set(self.hung)
        for info in infos:
            if info["name"] in self.bounds:
                quiet = silence(info, self.layout.beat(info["name"]), now)
                if quiet is not None:
                    self._judge(quiet, verdict(quiet, self.bounds[quiet.name]))
        if set(self.hung) - before:
            self.alerts.send("raise", "; ".join(self._said(name) for name in self.hung))
        elif before and not self.hung:
            self.alerts.send("resolve", f"{', '.join(sorted(before))} beating again")

    def _judge(self, quiet: Silence, said: str) -> None:
        if said == "ok":
            if quiet.beaten and self.hung.pop(quiet.name, None) is not None:
                self.say(f"{quiet.name} beating again", flush=True)
            return
        if quiet.name not in self.hung:
            self.hung[quiet.name] = quiet.seconds
            self.say(f"{self._said(quiet.name)}", flush=True)
        if said == "restart" and quiet.pid not in self.killed:
            self.killed.add(quiet.pid)
            kill(quiet.pid, f"{quiet.name}: no heartbeat for {quiet.seconds:.1f} s", self.say)

    def _said(self, name: str) -> str:
        return f"{name} process hung (no heartbeat for {self.hung[name]:.1f} s)"


def watch(layout: Layout, bounds: dict[str, Bounds], stopping: threading.Event) -> None:
    """Check every POLL_S until stopping; beat meanwhile."""
    socket.setdefaulttimeout(
        RPC_TIMEOUT_S
    )  # the supervisor's socket: a busy supervisor delays, never hangs us
    beat = Heartbeat(layout.beat("hangwatch"))
    watcher = Watcher(layout, bounds, Alerts().start())
    while not stopping.wait(POLL_S):
        beat.beat()
        try:
            infos = rpc(layout).supervisor.getAllProcessInfo()
        except (OSError, http.client.HTTPException, xmlrpc.client.Error):
            continue  # starting or stopping: asked again next time
        watcher.check(infos, time.time())


def parse_bound(text: str) -> tuple[str, Bounds]:
    name, alert_s, restart_s = text.split(":")
    return name, Bounds(float(alert_s), float(restart_s))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--var-dir", type=Path, required=True)
    parser.add_argument("watched", nargs="+", type=parse_bound, metavar="NAME:ALERT_S:RESTART_S")
    args = parser.parse_args(argv)
    stopping = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stopping.set())
    bounds = dict(args.watched)
    print(f"hangwatch: watching {', '.join(bounds)}", flush=True)
    watch(Layout(args.var_dir), bounds, stopping)
    return 0


if __name__ == "__main__":
    sys.exit(main())
