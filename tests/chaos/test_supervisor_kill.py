"""The whole `make run`: a hung links process is alerted on within 2 s and restarted; kill -9 of supervisord takes
every process with it within 5 s; `make run` again on the same folder starts cleanly; and `make run` itself killed
-9 leaves nothing behind (its supervisor is told to stop, and stops everything).

One `make run` for the module (tests in file order), then a second one on the same folder and ports.
"""

from __future__ import annotations

import contextlib
import datetime
import os
import signal
import sqlite3
import time
from contextlib import closing

import psutil
import pytest

from tests.chaos.system import STOP_TIMEOUT, RunningSystem, alive

pytestmark = [pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(600)]

ALERT_WITHIN = 2.0  # s from a hung links process to its alert (issue 31)
GONE_WITHIN = 5.0  # s from kill -9 of supervisord to no process of the run left (issue 30)
BACK_WITHIN = 60.0  # s for the supervisor to have started the killed links process again and it to beat


def hung_alerts(system: RunningSystem) -> list[tuple[str, str, str | None]]:
    """(message, raised_at, resolved_at) of process_hung alerts, from the database itself."""
    database = f"file:{system.var_dir / 'fleet.sqlite3'}?mode=ro"
    query = "SELECT message, raised_at, resolved_at FROM alerts_alert WHERE kind = 'process_hung' ORDER BY id"
    try:
        with closing(sqlite3.connect(database, uri=True, timeout=10)) as db:
            return db.execute(query).fetchall()
    except sqlite3.OperationalError:
        return []  # busy: asked again


def supervisord_pid(system: RunningSystem) -> int:
    return int((system.var_dir / "supervisord.pid").read_text())


def run_tree(system: RunningSystem) -> list[int]:
    """The supervisor and every process under it."""
    supervisor = psutil.Process(supervisord_pid(system))
    return [supervisor.pid, *(child.pid for child in supervisor.children(recursive=True))]


def gone_within(pids: list[int], timeout: float) -> None:
    """Every one of pids ended within timeout (polled every 50 ms)."""
    deadline = time.monotonic() + timeout
    while any(alive(pid) for pid in pids):
        if time.monotonic() > deadline:
            raise AssertionError(f"left after {timeout:g} s: {[pid for pid in pids if alive(pid)]}")
        time.sleep(0.05)


def test_a_stopped_links_process_is_alerted_on_within_2_s_and_restarted(system):
    before = len(hung_alerts(system))
    # a process not yet beating since its start is given minutes (Django loads slowly on a busy machine):
    # the hang this test makes is of a links process that has been working
    system.wait_until(lambda: system.beating("links"), BACK_WITHIN, "the links process beating")
    links = system.processes()["links"].pid
    os.kill(links, signal.SIGSTOP)
    stopped = time.time()
    try:
        system.wait_until(lambda: len(hung_alerts(system)) > before, 30, "a process_hung alert")
        message, raised_at, _ = hung_alerts(system)[-1]
        system.wait_until(lambda: not alive(links), 30, "the stopped links process killed")
        system.wait_until(lambda: system.back("links", links), BACK_WITHIN, "links running again")
        system.wait_until(lambda: hung_alerts(system)[-1][2] is not None, BACK_WITHIN, "the alert resolved")
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(links, signal.SIGCONT)
    assert message.startswith("links process hung (no heartbeat for ")
    alerted_s = datetime.datetime.fromisoformat(raised_at).replace(tzinfo=datetime.UTC).timestamp() - stopped
    assert alerted_s <= ALERT_WITHIN, f"alerted {alerted_s:.1f} s after links stopped ({message})"


def test_kill_9_of_supervisord_takes_every_process_and_make_run_again_starts_cleanly(system):
    tree = run_tree(system)
    assert len(tree) >= 9  # supervisord, redis, web, worker, control, sim, links, scheduler, hangwatch
    os.kill(tree[0], signal.SIGKILL)
    gone_within(tree, GONE_WITHIN)
    assert system.make.wait(timeout=STOP_TIMEOUT) != 0
    assert "the supervisor was killed (SIGKILL); every process went with it" in system.text()
    system.kill_leftovers()

    again = RunningSystem(system.var_dir, port=system.port, sim_port_base=system.sim_port_base).start()
    try:
        assert "make run:" not in again.text()  # nothing to end or wait for, nothing in the way
        names = [process.name for process in again.processes().values()]
        assert sorted(names) == sorted(set(names)) and {"redis", "links", "scheduler"} <= set(names)
        # `make run` itself killed -9: its supervisor is told to stop (SIGTERM), and stops every process
        second_tree = run_tree(again)
        run = next(
            child for child in psutil.Process(again.make.pid).children() if "fleet.run" in child.cmdline()
        )
        run.kill()
        gone_within(second_tree, STOP_TIMEOUT)
    finally:
        again.kill_leftovers()
