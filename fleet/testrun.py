"""`make test`: the whole suite, on the Redis and database the environment names, else the embedded defaults.

With no arguments it runs in two phases: every test not marked `alone` spread over FLEET_TEST_WORKERS pytest-xdist
workers (3 by default, one file per worker at a time: a file's fixtures, such as a simulated world, stay in one
process), then the `alone` tests (the multi-host cluster, the whole-system chaos runs: they load the machine with
a dozen processes and would starve the simulated worlds of the tests beside them) one at a time. Most tests wait
on simulated robots that drive in simulated time, so a worker uses a fifth of a core: three share two cores.
FLEET_TEST_WORKERS=0 runs everything in this one process, in one phase. With arguments, they go to one pytest
run as given.

Browser tests run wherever Debian's chromium (or FLEET_CHROMIUM) exists; elsewhere one line says they did not.
"""

import os
import sys
from pathlib import Path

from fleet.embedded_redis import call

BASE_DIR = Path(__file__).resolve().parent.parent
WORKERS = 3
ALONE = "alone"  # the marker of the tests that run after the parallel phase, one at a time (pyproject.toml)


def chromium_path() -> str | None:
    path = os.environ.get("FLEET_CHROMIUM", "/usr/bin/chromium")
    return path if Path(path).exists() else None


def phases(args: list[str], workers: int) -> list[list[str]]:
    """The pytest argument lists to run in turn: the arguments given as they are, or the two phases."""
    if args or workers <= 0:
        return [args]
    return [
        ["-n", str(workers), "--dist", "loadfile", "-m", f"not {ALONE}"],
        ["-m", ALONE],
    ]


def main() -> int:
    args = sys.argv[1:]
    browsers = chromium_path() is not None
    if not browsers:
        print(
            "make test: browser tests NOT run: no chromium at /usr/bin/chromium (set FLEET_CHROMIUM or apt-get install chromium)"
        )
    os.environ.setdefault("FLEET_REDIS_PREFIX", f"test{os.getpid()}")  # this run's own keys and groups
    os.environ.setdefault("FLEET_FAST_PASSWORD_HASH", "1")  # logins cheap for the suite (fleet/settings.py)
    os.environ.setdefault("PYTHONFAULTHANDLER", "1")  # a crash, even during interpreter exit, shows where
    print(
        "make test: database",
        os.environ.get("DATABASE_URL") or "SQLite (default)",
        "| redis",
        os.environ.get("REDIS_URL") or "embedded",
        flush=True,
    )
    runs = phases(args, int(os.environ.get("FLEET_TEST_WORKERS", WORKERS)))
    worst = 0
    for phase in runs:
        if not browsers:
            phase = _without_browsers(phase)
        command = [sys.executable, "-m", "pytest", *phase]
        if not os.environ.get("REDIS_URL"):
            command = [sys.executable, "-m", "fleet.embedded_redis", "exec", "--", *command]
        print("make test:", " ".join(["pytest", *phase]), flush=True)
        code = call(command, cwd=BASE_DIR)
        if len(runs) > 1 and code == 5:  # no test selected: a phase may be empty (e.g. -k in FLEET_TEST_ARGS)
            code = 0
        worst = worst or code
    return worst


def _without_browsers(phase: list[str]) -> list[str]:
    """The phase with browser tests deselected too (its own -m, if any, joined with `and`)."""
    if "-m" not in phase:
        return ["-m", "not browser", *phase]
    at = phase.index("-m") + 1
    return [*phase[:at], f"({phase[at]}) and not browser", *phase[at + 1 :]]


if __name__ == "__main__":
    sys.exit(main())
