"""The tiny exec wrapper in front of every process `make run`'s supervisor starts (run as a script: stdlib only).

    python -I fleet/procwrap.py [--parent-pidfile FILE] [--lock FILE [--lock-wait S]] -- COMMAND ARGS...

1. Die with the supervisor: the kernel's parent-death signal (prctl PR_SET_PDEATHSIG, SIGKILL) is set here and
   kept across exec, so when supervisord dies, even by kill -9, the kernel kills this process at once. No
   supervisord setting does this (it cleans up only when it stops normally), a process group can only be
   signalled by someone still alive to do it, and polling for the parent would be one more loop in every
   process; the kernel's signal needs none. SIGKILL, not SIGTERM: a graceful stop may take tens of seconds (a
   Celery warm shutdown waits for its tasks) and the run is over anyway; each process already survives a
   kill -9 of any other (tests/chaos/test_process_kill.py).
2. One of each per var folder: with --lock, an exclusive flock on FILE (waited for up to LOCK_WAIT_S, e.g. for
   the killed predecessor to be gone), held by the command itself (the descriptor is kept across exec), so two
   Redis servers, schedulers or links processes never run on one var folder, however they were started.
"""

import argparse
import contextlib
import ctypes
import fcntl
import os
import signal
import sys
import time

PR_SET_PDEATHSIG = 1
LOCK_WAIT_S = 10.0
HEARTBEAT_ENV = "FLEET_HEARTBEAT"  # fleetcore.heartbeat.ENV


def die_with_parent(pidfile: str | None = None) -> None:
    """SIGKILL this process when its parent ends; exit at once if the parent already has (it is not the pid in
    pidfile, the supervisor's, written before it starts anything; or, without one, not who it was a moment ago)."""
    parent = _pid_in(pidfile) if pidfile else os.getppid()
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the parent died before the signal was set: it will never come
        sys.exit("procwrap: the supervisor is gone; not starting")


def _pid_in(path: str) -> int:
    try:
        with open(path) as file:
            return int(file.read().strip() or 0)
    except (OSError, ValueError):
        return 0


def hold_lock(path: str, wait: float = LOCK_WAIT_S) -> int:
    """An exclusive flock on path, kept open across exec (its holder's pid written in it)."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    deadline = time.monotonic() + wait
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except BlockingIOError:
            if time.monotonic() > deadline:
                holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
                sys.exit(f"procwrap: {path} is held by pid {holder}: another one runs on this var folder")
            time.sleep(0.1)
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    os.set_inheritable(fd, True)
    return fd


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parent-pidfile", help="the supervisor's pidfile: its pid is our parent's")
    parser.add_argument("--lock", help="hold an exclusive lock on this file for the command's life")
    parser.add_argument("--lock-wait", type=float, default=LOCK_WAIT_S, help="seconds to wait for the lock")
    parser.add_argument("command", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("a command is needed after --")
    die_with_parent(args.parent_pidfile)
    if args.lock:
        hold_lock(args.lock, args.lock_wait)
    if os.environ.get(HEARTBEAT_ENV):  # a beat left by the one before is not this one's (fleet/hangwatch.py)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(os.environ[HEARTBEAT_ENV])
    sys.stdout.flush()
    os.execvp(command[0], command)


if __name__ == "__main__":
    main(sys.argv[1:])
