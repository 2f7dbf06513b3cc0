"""One `make run` per var folder: its lock, the leftovers of an earlier run, and the ports and socket it needs.

Before anything starts, `make run`:

1. takes var/proc/run.lock (an exclusive fcntl lock, our pid written in it), and hands it to supervisord too, so
   the lock is held while either lives. Held by a live `make run`: we refuse at once (two runs on one var folder
   would be two Redis servers, two schedulers, two links processes against one database). Held by a run whose
   `make run` is gone (its supervisord still stopping its processes): we wait for it, up to LOCK_WAIT_S.
2. ends every process still marked as a process of a run of this var folder (RUN_ENV in its environment: every
   process the supervisor starts has it), saying so: what a run that lost its supervisor left behind. Every
   process dies with its supervisor (fleet/procwrap.py), so this finds something only after a failure of that.
3. checks that the portal's port, the simulator's ports and the embedded Redis's socket are free, and refuses,
   naming the holder, if one is not: something else (not a run of this folder) holds it.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import psutil

RUN_ENV = "FLEET_RUN"  # the var folder of the run a process belongs to
LOCK_WAIT_S = 60.0  # for an earlier run's supervisor to finish stopping its processes
END_GRACE_S = 5.0  # after SIGTERM, before SIGKILL, for a leftover


class Refused(RuntimeError):
    """`make run` cannot start here; the message says why and what to do."""


@dataclass(frozen=True)
class Needs:
    """What one run holds: its var folder, TCP ports on 127.0.0.1, and a unix socket (or None)."""

    var_dir: Path
    ports: tuple[int, ...]
    redis_socket: Path | None


def take_lock(path: Path, say=print, wait: float = LOCK_WAIT_S) -> int:
    """The run lock's descriptor (inheritable: supervisord keeps it); Refused if a live `make run` holds it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    deadline, said = time.monotonic() + wait, False
    while not _locked(fd):
        holder = _holder(fd)
        if holder is not None and _is_run(holder):
            os.close(fd)
            raise Refused(
                f"another `make run` (pid {holder}) uses {path.parent.parent}: stop it first (Ctrl-C there)"
            )
        if time.monotonic() > deadline:
            os.close(fd)
            raise Refused(f"an earlier run's processes still hold {path} after {wait:.0f} s")
        if not said:
            say(f"make run: waiting for an earlier run's processes to stop (they hold {path})")
            said = True
        time.sleep(0.2)
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    os.set_inheritable(fd, True)
    return fd


def _locked(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _holder(fd: int) -> int | None:
    text = os.pread(fd, 32, 0).decode(errors="replace").strip()
    return int(text) if text.isdigit() else None


def _is_run(pid: int) -> bool:
    """Whether pid is a live `make run` (fleet.run), not a supervisor left stopping after it."""
    with contextlib.suppress(psutil.Error):
        return "fleet.run" in psutil.Process(pid).cmdline()
    return False


def leftovers(var_dir: Path) -> list[psutil.Process]:
    """Processes (of our user) of a run of this var folder, other than us and our ancestors."""
    ours = {os.getpid(), *(parent.pid for parent in psutil.Process().parents())}
    found = []
    for process in psutil.process_iter(["uids"]):
        if process.pid in ours or process.info["uids"] is None or process.info["uids"].real != os.getuid():
            continue
        with contextlib.suppress(psutil.Error):
            if process.environ().get(RUN_ENV) == str(var_dir):
                found.append(process)
    return found


def end(processes: list[psutil.Process], grace: float = END_GRACE_S) -> None:
    """SIGTERM them, SIGKILL those left after grace."""
    for process in processes:
        with contextlib.suppress(psutil.Error):
            process.terminate()
    _, alive = psutil.wait_procs(processes, timeout=grace)
    for process in alive:
        with contextlib.suppress(psutil.Error):
            process.kill()
    psutil.wait_procs(alive, timeout=grace)


def end_leftovers(var_dir: Path, say=print) -> int:
    """End what an earlier run of this folder left, saying so; how many there were."""
    found = leftovers(var_dir)
    if found:
        names = ", ".join(f"{process.pid} ({describe(process)})" for process in found)
        say(f"make run: ending {len(found)} process(es) an earlier run of {var_dir} left: {names}")
        end(found)
    return len(found)


def busy(needs: Needs) -> list[str]:
    """What is not free among what the run needs, each said with its holder."""
    problems = [
        f"port {port} is in use{_by(_listener(port))}" for port in needs.ports if not _port_free(port)
    ]
    if needs.redis_socket is not None and _socket_answers(needs.redis_socket):
        problems.append(f"something listens on {needs.redis_socket}")
    return problems


def _port_free(port: int) -> bool:
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the servers bind: TIME_WAIT is free
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _socket_answers(path: Path) -> bool:
    with socket.socket(socket.AF_UNIX) as sock:
        sock.settimeout(1)
        try:
            sock.connect(str(path))
        except OSError:
            return False  # missing, or a file left by a killed server
    return True


def _listener(port: int) -> psutil.Process | None:
    with contextlib.suppress(psutil.Error):
        for conn in psutil.net_connections("inet"):
            if conn.laddr and conn.laddr.port == port and conn.status == psutil.CONN_LISTEN and conn.pid:
                return psutil.Process(conn.pid)
    return None


def _by(process: psutil.Process | None) -> str:
    return f" by pid {process.pid} ({describe(process)})" if process is not None else ""


def describe(process: psutil.Process) -> str:
    with contextlib.suppress(psutil.Error):
        return " ".join(process.cmdline())[:80] or process.name()
    return "?"


def guard(needs: Needs, lock: Path, say=print) -> int:
    """All of the above, in order; the run lock's descriptor. Refused if the run cannot start."""
    fd = take_lock(lock, say)
    try:
        end_leftovers(needs.var_dir, say)
        problems = busy(needs)
        if problems:
            raise Refused(
                "; ".join(problems) + ": not starting over it (FLEET_PORT, FLEET_SIM_PORT_BASE choose others)"
            )
    except BaseException:
        os.close(fd)
        raise
    return fd
