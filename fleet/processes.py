"""Fleet processes started next to this one (Celery workers, the scheduler) that share its database, Redis and
keys: how benches and tests run real workers against the state they set up.

    proc = start([sys.executable, "-m", "celery", "-A", "fleet", "worker", "-Q", queue], fleet_env())
    ...
    end(proc)

Each process leads a session of its own, so end() stops it with all its children (a prefork pool's too).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
from pathlib import Path
from urllib.parse import quote

from django.conf import settings
from django.db import connection

BASE_DIR = Path(__file__).resolve().parent.parent
STOP_GRACE_S = 10.0  # after SIGTERM, before SIGKILL
POSTGRES_PORT = 5432


def database_url(db: dict) -> str:
    """A Django database (a DATABASES entry) as a DATABASE_URL another process can open."""
    if db["ENGINE"].endswith("sqlite3"):
        if "memory" in str(db["NAME"]):
            raise ValueError("the database is in memory; another process cannot share it")
        return f"sqlite:///{db['NAME']}"
    user, password = quote(db["USER"] or "", safe=""), quote(db["PASSWORD"] or "", safe="")
    host = quote(db["HOST"] or "127.0.0.1", safe="")  # a socket directory's slashes quoted too
    return f"postgres://{user}:{password}@{host}:{db['PORT'] or POSTGRES_PORT}/{db['NAME']}"


def fleet_env() -> dict[str, str]:
    """This process's environment with what a fleet process needs to share its database, Redis, keys and world (as
    they are in settings now, which a test may have changed since start-up)."""
    shared = {
        "DJANGO_SETTINGS_MODULE": settings.SETTINGS_MODULE,
        "DATABASE_URL": database_url(connection.settings_dict),
        "REDIS_URL": settings.REDIS_URL,
        "FLEET_REDIS_PREFIX": settings.CACHES["default"].get("KEY_PREFIX"),
        "FLEET_EXEC_KEY_PREFIX": getattr(settings, "FLEET_EXEC_KEY_PREFIX", None),
        "FLEET_WORLD": getattr(settings, "FLEET_WORLD", None),
    }
    return {**os.environ, **{name: str(value) for name, value in shared.items() if value is not None}}


def start(command: list[str], env: dict[str, str]) -> subprocess.Popen:
    """Start a command in the project directory, in a session of its own (its group is end()'s to stop)."""
    return subprocess.Popen(command, cwd=BASE_DIR, env=env, start_new_session=True)


def end(proc: subprocess.Popen, grace: float = STOP_GRACE_S) -> None:
    """SIGTERM the process group, SIGKILL it if it has not gone within `grace` seconds."""
    with contextlib.suppress(ProcessLookupError):  # it may have gone (or been killed) already
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(grace)
