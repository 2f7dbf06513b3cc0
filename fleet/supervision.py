"""`make run`'s supervisor: supervisord runs every process and starts again any that dies.

supervisord (the `supervisor` package) restarts at once a process that dies after it was up, and one that dies
within START_SECONDS of its start after one more second each time (1 s, 2 s, 3 s, ...), START_RETRIES times in a
row before it gives up; each death is one line of its log. Every process writes to var/log/<name>.log, and
LogRelay prints those lines to the terminal with the process's name in front, as one merged stream.

This module only writes the configuration and reads what supervisord says; fleet/run.py decides what runs.
"""

from __future__ import annotations

import ctypes
import http.client
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
import xmlrpc.client
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from supervisor.xmlrpc import SupervisorTransport

START_SECONDS = 3  # a process up this long counts as started; one that dies sooner backs off
START_RETRIES = 1000  # quick deaths in a row before supervisord gives up on a process (backing off: hours)
LOG_BYTES, LOG_BACKUPS = 10 * 1024 * 1024, 2  # per process log under var/log/ (Django's logs go there too)
PROCWRAP = Path(__file__).resolve().with_name("procwrap.py")
HEARTBEAT_ENV = "FLEET_HEARTBEAT"  # fleetcore.heartbeat.ENV: the file a watched process beats


@dataclass(frozen=True)
class Bounds:
    """How long a process may go without a heartbeat: an alert past alert_s, a restart past restart_s."""

    alert_s: float
    restart_s: float


@dataclass(frozen=True)
class Program:
    """One supervised process."""

    name: str
    command: list[str]
    # Redis starts with the supervisor; run.py starts the rest once the database is migrated
    autostart: bool = False
    priority: int = 100  # started in ascending order, stopped in descending order
    stop_seconds: int = 10  # after SIGTERM, then SIGKILL
    group: str | None = "fleet"  # a group's processes are stopped together; None: a group of its own
    single: bool = False  # one per var folder, always: it holds var/proc/<name>.lock (fleet/procwrap.py)
    hung: Bounds | None = None  # it beats (var/proc/<name>.beat); silent this long: alert, then restart


@dataclass(frozen=True)
class Layout:
    """Where one supervisor keeps its files: all under one var/ folder."""

    var_dir: Path

    @property
    def config(self) -> Path:
        return self.var_dir / "supervisord.conf"

    @property
    def pidfile(self) -> Path:
        return self.var_dir / "supervisord.pid"

    @property
    def socket(self) -> Path:
        return self.var_dir / "supervisor.sock"

    @property
    def log_dir(self) -> Path:
        return self.var_dir / "log"

    def log(self, name: str) -> Path:
        return self.log_dir / f"{name}.log"

    @property
    def proc_dir(self) -> Path:
        """The run's lock, each single process's lock and each watched process's heartbeat."""
        return self.var_dir / "proc"

    @property
    def run_lock(self) -> Path:
        return self.proc_dir / "run.lock"

    def lock(self, name: str) -> Path:
        return self.proc_dir / f"{name}.lock"

    def beat(self, name: str) -> Path:
        return self.proc_dir / f"{name}.beat"


def render_config(programs: list[Program], layout: Layout, directory: Path) -> str:
    """supervisord.conf for these programs, run in the foreground, listening only on a unix socket."""
    lines = [
        "; written by fleet/run.py at each start: edit fleet/run.py, not this file",
        "[supervisord]",
        "nodaemon = true",
        "silent = true",
        f"logfile = {layout.log('supervisord')}",
        f"logfile_maxbytes = {LOG_BYTES}",
        f"logfile_backups = {LOG_BACKUPS}",
        "loglevel = info",
        f"pidfile = {layout.pidfile}",
        f"childlogdir = {layout.log_dir}",
        f"directory = {directory}",
        "",
        "[unix_http_server]",
        f"file = {layout.socket}",
        "chmod = 0700",
        "",
        "[rpcinterface:supervisor]",
        "supervisor.rpcinterface_factory = supervisor.rpcinterface:make_main_rpcinterface",
        "",
        "[supervisorctl]",
        f"serverurl = unix://{layout.socket}",
    ]
    for program in programs:
        lines += ["", *program_section(program, layout, directory)]
    for group in dict.fromkeys(program.group for program in programs if program.group):
        members = [program for program in programs if program.group == group]
        lines += ["", f"[group:{group}]", f"programs = {','.join(program.name for program in members)}"]
        lines += [f"priority = {min(program.priority for program in members)}"]
    return "\n".join(lines) + "\n"


def program_section(program: Program, layout: Layout, directory: Path) -> list[str]:
    """One [program:x] section; `%` is supervisord's expansion character, so a literal one is doubled."""
    beat = [f'environment = {HEARTBEAT_ENV}="{layout.beat(program.name)}"'] if program.hung else []
    return [
        f"[program:{program.name}]",
        f"command = {shlex.join(wrapped(program, layout)).replace('%', '%%')}",
        *[line.replace("%", "%%") for line in beat],
        f"directory = {directory}",
        f"priority = {program.priority}",
        f"autostart = {str(program.autostart).lower()}",
        "autorestart = true",
        f"startsecs = {START_SECONDS}",
        f"startretries = {START_RETRIES}",
        "stopsignal = TERM",
        f"stopwaitsecs = {program.stop_seconds}",
        "stopasgroup = true",
        "killasgroup = true",
        "redirect_stderr = true",
        f"stdout_logfile = {layout.log(program.name)}",
        f"stdout_logfile_maxbytes = {LOG_BYTES}",
        f"stdout_logfile_backups = {LOG_BACKUPS}",
    ]


def wrapped(program: Program, layout: Layout) -> list[str]:
    """The program's command behind fleet/procwrap.py: it dies with the supervisor, a single one holds its lock."""
    lock = ["--lock", str(layout.lock(program.name))] if program.single else []
    parent = ["--parent-pidfile", str(layout.pidfile)]
    return [sys.executable, "-I", str(PROCWRAP), *parent, *lock, "--", *program.command]


def start_supervisord(
    layout: Layout, env: dict[str, str], keep_fds: tuple[int, ...] = ()
) -> subprocess.Popen:
    """supervisord in the foreground, as our child, in a process group of its own: the terminal's signals (a
    Ctrl-C, a hang-up, which supervisord would take as "reload") reach only us, and we tell it to stop. On Linux
    it is also told to stop if we are killed (and its processes die with it: fleet/procwrap.py). keep_fds: ours
    it holds too (the run lock)."""
    layout.proc_dir.mkdir(parents=True, exist_ok=True)
    return subprocess.Popen(
        [sys.executable, "-m", "supervisor.supervisord", "-c", str(layout.config)],
        env=env,
        stdout=subprocess.DEVNULL,
        pass_fds=keep_fds,
        process_group=0,
        preexec_fn=_stop_with_parent if sys.platform == "linux" else None,
    )


def _stop_with_parent() -> None:
    """SIGTERM this child when the thread that started it ends (prctl PR_SET_PDEATHSIG)."""
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)


def rpc(layout: Layout) -> xmlrpc.client.ServerProxy:
    """supervisord's XML-RPC interface over its unix socket (what `supervisorctl` uses)."""
    transport = SupervisorTransport(None, None, f"unix://{layout.socket}")
    return xmlrpc.client.ServerProxy("http://127.0.0.1", transport=transport)


def wait_for_rpc(layout: Layout, supervisord: subprocess.Popen, timeout: float = 20.0):
    """The RPC proxy once our supervisord answers on it; None if it ended (e.g. another one holds the socket: a
    second `make run` in the same var/ folder) or did not answer in time."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and supervisord.poll() is None:
        proxy = rpc(layout)  # a fresh connection each time: a failed one is not reused
        try:
            ours = proxy.supervisor.getPID() == supervisord.pid
            if ours and proxy.supervisor.getState()["statename"] == "RUNNING":
                return proxy
        except (OSError, http.client.HTTPException, xmlrpc.client.Fault):
            pass  # not listening yet
        time.sleep(0.1)
    return None


# supervisord's own log: only what a person must see reaches the terminal (a death, giving up, a kill), once.
SUPERVISOR_LINE = re.compile(r"^\S+ \S+ (?P<level>[A-Z]+) (?P<text>.*)$")
SUPERVISOR_SHOWN = {"WARN", "ERRO", "CRIT"}
SUPERVISOR_QUIET = (  # said at every start, and answered here: the socket is 0700 in var/, run as whoever runs it
    "running without any HTTP authentication checking",
    "Supervisor is running as root",
)


def supervisor_line(line: str) -> str | None:
    """The part of one supervisord log line worth printing, or None."""
    match = SUPERVISOR_LINE.match(line)
    if not match:
        return None
    text = match["text"]
    if text.startswith("gave up:") or (
        match["level"] in SUPERVISOR_SHOWN and not any(quiet in text for quiet in SUPERVISOR_QUIET)
    ):
        return text
    return None


class Tail:
    """New lines of one log file, from where it ended when this was made, across supervisord's rotations."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.handle = None
        self.buffer = b""
        stat = path.stat() if path.exists() else None
        self.start = (stat.st_ino, stat.st_size) if stat else None

    def lines(self) -> list[str]:
        if self.handle is None and not self._open():
            return []
        replaced = self._replaced()
        data = self.handle.read()
        if replaced:  # rotated away: its last lines are read now, the new file is opened at the next poll
            self.handle.close()
            self.handle = None
        complete, _, self.buffer = (self.buffer + data).rpartition(b"\n")
        return complete.decode("utf-8", "replace").splitlines() if complete else []

    def _open(self) -> bool:
        try:
            self.handle = open(self.path, "rb")  # noqa: SIM115 - kept open across polls
        except FileNotFoundError:
            return False
        stat = os.fstat(self.handle.fileno())
        if self.start and self.start[0] == stat.st_ino:
            self.handle.seek(self.start[1])  # the file of an earlier run: only what comes now
        self.start = None
        return True

    def _replaced(self) -> bool:
        try:
            return os.stat(self.path).st_ino != os.fstat(self.handle.fileno()).st_ino
        except FileNotFoundError:
            return True

    def close(self) -> None:
        if self.handle is not None:
            self.handle.close()


class LogRelay:
    """Prints each process's new log lines as `hh:mm:ss name | line`, polling a few times a second."""

    def __init__(self, layout: Layout, names: list[str], out: TextIO = sys.stdout, period: float = 0.2):
        self.tails = {"supervisor": Tail(layout.log("supervisord"))}
        self.tails.update((name, Tail(layout.log(name))) for name in names)
        self.width = max(len(name) for name in self.tails)
        self.out, self.period = out, period
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, name="log relay", daemon=True)

    def start(self) -> LogRelay:
        self.thread.start()
        return self

    def stop(self) -> None:
        """Print what is left and stop."""
        self.done.set()
        self.thread.join(timeout=5)
        for tail in self.tails.values():
            tail.close()

    def _run(self) -> None:
        while True:
            finished = self.done.wait(self.period)
            self.flush()
            if finished:
                return

    def flush(self) -> None:
        stamp = time.strftime("%H:%M:%S")
        for name, tail in self.tails.items():
            for line in tail.lines():
                shown = supervisor_line(line) if name == "supervisor" else line
                if shown is not None:
                    self.out.write(f"{stamp} {name:<{self.width}} | {shown}\n")
        self.out.flush()
