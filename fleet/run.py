"""`make run`: migrate, set up the demo, then start every process of the system under one honcho manager.

One Ctrl-C stops them all; nothing is left running or listening.
"""

import os
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

from honcho.manager import Manager

from fleet import embedded_redis

BASE_DIR = Path(__file__).resolve().parent.parent
HOST, PORT = "127.0.0.1", int(os.environ.get("FLEET_PORT", "8000"))


def processes(python: str) -> dict[str, str]:
    """The system's processes, each a shell command (honcho runs them and merges their output)."""
    manage = f"{python} manage.py"
    world = os.environ.get("FLEET_WORLD", "paper")  # the simulated world (fleetcore/worlds/<name>)
    procs = {
        "web": f"{python} -m uvicorn fleet.asgi:application --host {HOST} --port {PORT} --log-level warning",
        # Instructions block while robots move, so that worker runs many threads; stops and registrations
        # have a worker of their own and never wait behind a long instruction.
        "worker": f"{python} -m celery -A fleet -q worker -n instructions@%h -Q instructions -P threads -c 32 -l warning",
        "control": f"{python} -m celery -A fleet -q worker -n control@%h -Q control,registration -c 1 -l warning",
        "sim": f"{manage} simworker --world {world}",
        "links": f"{manage} robotlinks --register-world {world}",
        "scheduler": f"{manage} scheduler",  # time slots, lost workers, stalled robot queues (issue 6)
    }
    return procs


def main() -> int:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    if os.environ.get("REDIS_URL"):
        return start_all(env)
    socket_path = BASE_DIR / "var" / "redis.sock"
    redis = embedded_redis.start(socket_path)
    print(f"embedded Redis at unix://{socket_path}", flush=True)
    try:
        return start_all({**env, "REDIS_URL": f"unix://{socket_path}"})
    finally:
        embedded_redis.stop(redis, socket_path)


def start_all(env: dict) -> int:
    python = sys.executable
    subprocess.run(
        [python, "manage.py", "migrate", "--noinput", "-v", "0"], cwd=BASE_DIR, env=env, check=True
    )
    # its output is kept to say the login again later; its errors go straight to the terminal
    demo = subprocess.run(
        [python, "manage.py", "setup_demo"], cwd=BASE_DIR, env=env, stdout=subprocess.PIPE, text=True
    )
    print(demo.stdout, end="", flush=True)
    if demo.returncode:
        return demo.returncode
    login = next((line for line in demo.stdout.splitlines() if line.startswith("login:")), "")
    manager = Manager()
    for name, command in processes(python).items():
        manager.add_process(name, command, cwd=str(BASE_DIR), env=env)
    url = f"http://{HOST}:{PORT}/"
    print(f"\n  Fleet portal: {url}  (starting; Ctrl-C stops everything)\n", flush=True)
    threading.Thread(target=lambda: print(announcement(url, login), flush=True), daemon=True).start()
    manager.loop()
    return manager.returncode or 0


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
