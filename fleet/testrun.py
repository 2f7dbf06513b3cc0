"""`make test`: the whole suite, on the Redis and database the environment names, else the embedded defaults.

Browser tests run wherever Debian's chromium (or FLEET_CHROMIUM) exists; elsewhere one line says they did not.
"""

import os
import sys
from pathlib import Path

from fleet.embedded_redis import call

BASE_DIR = Path(__file__).resolve().parent.parent


def chromium_path() -> str | None:
    path = os.environ.get("FLEET_CHROMIUM", "/usr/bin/chromium")
    return path if Path(path).exists() else None


def main() -> int:
    args = sys.argv[1:]
    if chromium_path() is None:
        print(
            "make test: browser tests NOT run: no chromium at /usr/bin/chromium (set FLEET_CHROMIUM or apt-get install chromium)"
        )
        args = ["-m", "not browser", *args]
    os.environ.setdefault("FLEET_REDIS_PREFIX", f"test{os.getpid()}")  # this run's own keys and groups
    os.environ.setdefault("FLEET_FAST_PASSWORD_HASH", "1")  # logins cheap for the suite (fleet/settings.py)
    os.environ.setdefault("PYTHONFAULTHANDLER", "1")  # a crash, even during interpreter exit, shows where
    command = [sys.executable, "-m", "pytest", *args]
    if not os.environ.get("REDIS_URL"):
        command = [sys.executable, "-m", "fleet.embedded_redis", "exec", "--", *command]
    print(
        "make test: database",
        os.environ.get("DATABASE_URL") or "SQLite (default)",
        "| redis",
        os.environ.get("REDIS_URL") or "embedded",
        flush=True,
    )
    return call(command, cwd=BASE_DIR)


if __name__ == "__main__":
    sys.exit(main())
