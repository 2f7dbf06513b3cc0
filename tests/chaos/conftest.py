"""The chaos tests' system (one `make run` for the module) and the table of what each fault cost."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import pytest

from tests.chaos.system import RunningSystem

FIGURES: list[dict] = []  # one row per fault, printed at the end of the run (docs/fault-survival.md)
OUT = "FLEET_CHAOS_OUT"  # a JSON file for the rows as well (python -m bench.chaos sets it)


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    """`make run`, whole, in a var folder and on ports of its own; ended at the end of the module if a test did
    not end it."""
    running = RunningSystem(tmp_path_factory.mktemp("make-run"))
    try:
        yield running.start()
    finally:
        if running.make is not None and running.make.poll() is None:
            running.interrupt()
        running.kill_leftovers()


@pytest.fixture
def figures():
    """Where a fault test puts its row."""
    return FIGURES


def pytest_terminal_summary(terminalreporter):
    if not FIGURES:
        return
    if os.environ.get(OUT):
        Path(os.environ[OUT]).write_text(json.dumps(_document(), indent=2) + "\n")
    columns = list(FIGURES[0])
    terminalreporter.section("fault survival (kill -9 of one process of `make run`)")
    terminalreporter.write_line("| " + " | ".join(columns) + " |")
    terminalreporter.write_line("|" + "---|" * len(columns))
    for row in FIGURES:
        terminalreporter.write_line("| " + " | ".join(str(row[column]) for column in columns) + " |")


def _document() -> dict:
    return {
        "what": "kill -9 of one process of `make run` while the turtlebot drives an instruction (tests/chaos/)",
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "faults": FIGURES,
    }
