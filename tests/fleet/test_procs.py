"""`make run`'s processes: they die with the supervisor, one run (and one single process) per var folder, a hung
process is alerted on and restarted, the embedded Redis's append-only file stays bounded.

Small supervisors of dummy programs here (seconds each); tests/chaos/test_supervisor_kill.py does the same to the
whole `make run`.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from fleet import runguard
from fleet.hangwatch import Watcher
from fleet.supervision import (
    PROCWRAP,
    Bounds,
    Layout,
    Program,
    render_config,
    rpc,
    start_supervisord,
    wait_for_rpc,
)
from simworker.testing import free_port

SLEEPER = [sys.executable, "-c", "import time; time.sleep(120)"]
BEATER = (  # beats its file every 0.05 s from an event loop, as the fleet's processes do (fleetcore/heartbeat.py)
    "import asyncio, sys; from fleetcore.heartbeat import Heartbeat; asyncio.run(Heartbeat(sys.argv[1]).run(0.05))"
)
BEATER_FROM_ENV = (  # the same, at the file the supervisor names (FLEET_HEARTBEAT)
    "import asyncio; from fleetcore import heartbeat; asyncio.run(heartbeat.from_env().run(0.05))"
)
BASE_DIR = Path(__file__).resolve().parents[2]


def wait_for(condition, timeout: float, what: str) -> float:
    """Seconds until condition() held (polled every 50 ms); AssertionError after timeout."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if condition():
            return time.monotonic() - start
        time.sleep(0.05)
    raise AssertionError(f"not within {timeout:g} s: {what}")


def alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


# ----- the supervisor's death is its processes' death -----


def test_a_supervisor_killed_with_sigkill_takes_every_process_with_it(tmp_path):
    layout = Layout(tmp_path)
    layout.log_dir.mkdir()
    listed = [
        Program("plain", SLEEPER, autostart=True),
        Program("single", SLEEPER, autostart=True, single=True),
        Program("beating", SLEEPER, autostart=True, hung=Bounds(1, 5)),
    ]
    layout.config.write_text(render_config(listed, layout, BASE_DIR))
    supervisord = start_supervisord(layout, dict(os.environ))
    try:
        proxy = wait_for_rpc(layout, supervisord)
        assert proxy is not None, "the supervisor did not start"
        wait_for(lambda: all(info["pid"] for info in proxy.supervisor.getAllProcessInfo()), 30, "all started")
        pids = [info["pid"] for info in proxy.supervisor.getAllProcessInfo()]
        assert len(pids) == 3
        supervisord.kill()
        supervisord.wait(10)
        wait_for(lambda: not any(alive(pid) for pid in pids), 5.0, f"{pids} gone with their supervisor")
    finally:
        if supervisord.poll() is None:
            supervisord.kill()
        for pid in pids if "pids" in locals() else []:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)


def _wrapped(lock: Path, wait: float = 10.0, **env) -> subprocess.Popen:
    command = [
        sys.executable,
        "-I",
        str(PROCWRAP),
        "--lock",
        str(lock),
        "--lock-wait",
        str(wait),
        "--",
        *SLEEPER,
    ]
    return subprocess.Popen(command, env={**os.environ, **env}, stderr=subprocess.PIPE, text=True)


def _holder(lock: Path) -> str:
    return lock.read_text().strip() if lock.exists() else ""


def test_a_single_process_holds_its_lock_and_a_second_one_gives_up_naming_the_holder(tmp_path):
    lock, beat = tmp_path / "links.lock", tmp_path / "links.beat"
    beat.write_text("")  # the last one's beat: not this one's
    first = _wrapped(lock, FLEET_HEARTBEAT=str(beat))
    try:
        wait_for(lambda: _holder(lock) == str(first.pid), 10, "the first holds the lock")
        assert not beat.exists()
        second = _wrapped(lock, wait=0.5)
        _, said = second.communicate(timeout=30)
        assert second.returncode != 0 and f"held by pid {first.pid}" in said
        assert first.poll() is None
    finally:
        first.kill()
        first.wait()
    third = _wrapped(lock, wait=5)  # the holder gone: the lock is free again
    try:
        wait_for(lambda: _holder(lock) == str(third.pid), 10, "the next one holds the lock")
    finally:
        third.kill()
        third.wait()


# ----- one run per var folder -----


def _needs(tmp_path, *ports, redis_socket=None) -> runguard.Needs:
    return runguard.Needs(tmp_path, ports or (free_port(),), redis_socket)


def test_an_earlier_runs_leftovers_are_ended_and_said_and_no_one_elses(tmp_path):
    ours = subprocess.Popen(SLEEPER, env={**os.environ, runguard.RUN_ENV: str(tmp_path)})
    other = subprocess.Popen(SLEEPER, env={**os.environ, runguard.RUN_ENV: str(tmp_path / "elsewhere")})
    said: list[str] = []
    try:
        fd = runguard.guard(_needs(tmp_path), Layout(tmp_path).run_lock, say=said.append)
        os.close(fd)
        assert ours.wait(10) is not None and other.poll() is None
        assert len(said) == 1 and f"{ours.pid} (" in said[0] and "left" in said[0]
    finally:
        for process in (ours, other):
            process.kill()
            process.wait()


def test_a_port_in_use_or_a_socket_answering_is_refused_naming_it(tmp_path):
    with socket.socket() as taken, socket.socket(socket.AF_UNIX) as redis_like:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        redis_like.bind(str(tmp_path / "redis.sock"))
        redis_like.listen()
        needs = _needs(tmp_path, port, free_port(), redis_socket=tmp_path / "redis.sock")
        with pytest.raises(runguard.Refused) as refused:
            runguard.guard(needs, Layout(tmp_path).run_lock, say=print)
    said = str(refused.value)
    assert f"port {port} is in use by pid {os.getpid()}" in said and "listens on" in said
    os.close(runguard.take_lock(Layout(tmp_path).run_lock))  # a refusal leaves the lock free


def _holding(lock: Path, *argv: str) -> subprocess.Popen:
    """A process that takes the run lock as `make run` does and keeps it; argv: its command line's tail."""
    code = "import sys, time; from fleet.runguard import take_lock; take_lock(__import__('pathlib').Path(sys.argv[1])); print('held', flush=True); time.sleep(60)"
    process = subprocess.Popen(
        [sys.executable, "-c", code, str(lock), *argv], cwd=BASE_DIR, stdout=subprocess.PIPE, text=True
    )
    assert process.stdout.readline().strip() == "held"
    return process


def test_a_live_run_is_refused_at_once_and_a_stopping_one_waited_for(tmp_path):
    lock = Layout(tmp_path).run_lock
    run = _holding(lock, "fleet.run")  # its command line says `python ... fleet.run`, as `make run`'s does
    try:
        with pytest.raises(runguard.Refused, match=f"another `make run` \\(pid {run.pid}\\)"):
            runguard.take_lock(lock, wait=30)
    finally:
        run.kill()
        run.wait()
    stopping = _holding(lock)  # not a run: a supervisor still stopping an earlier run's processes
    said: list[str] = []
    try:
        with pytest.raises(runguard.Refused, match="still hold"):
            runguard.take_lock(lock, say=said.append, wait=0.5)
        assert said and "waiting for an earlier run" in said[0]
    finally:
        stopping.kill()
        stopping.wait()
    os.close(runguard.take_lock(lock, wait=5))


# ----- a hung process: alerted on, then restarted -----


class _Alerts:
    def __init__(self):
        self.sent: list[tuple[str, str]] = []

    def send(self, action: str, text: str) -> None:
        self.sent.append((action, text))


def _beater(beat: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", BEATER, str(beat)], cwd=BASE_DIR, start_new_session=True)


def test_a_stopped_process_is_alerted_on_once_then_killed_and_its_successor_resolves_it(tmp_path):
    layout = Layout(tmp_path)
    alerts = _Alerts()
    watcher = Watcher(layout, {"links": Bounds(alert_s=0.3, restart_s=1.0)}, alerts, say=lambda *a, **k: None)
    process = _beater(layout.beat("links"))
    starts = {process.pid: time.time() - 100}  # settled long ago: its silences are alerted on

    def check(proc) -> None:
        info = {"name": "links", "pid": proc.pid, "statename": "RUNNING", "start": starts[proc.pid]}
        watcher.check([info], time.time())

    try:
        wait_for(lambda: layout.beat("links").exists(), 30, "the first beat")
        for _ in range(10):  # beating: nothing to say
            check(process)
            time.sleep(0.05)
        assert alerts.sent == []
        process.send_signal(signal.SIGSTOP)
        wait_for(lambda: check(process) or alerts.sent, 5, "the alert")
        assert alerts.sent[0][0] == "raise" and alerts.sent[0][1].startswith(
            "links process hung (no heartbeat"
        )
        wait_for(lambda: check(process) or process.poll() is not None, 5, "the stopped process killed")
        assert process.returncode == -signal.SIGKILL and len(alerts.sent) == 1  # one alert for the event
        layout.beat("links").unlink()  # as the wrapper does at each start
        successor = _beater(layout.beat("links"))  # as the supervisor starts it again
        starts[successor.pid] = time.time()
        wait_for(lambda: check(successor) or len(alerts.sent) == 2, 30, "the successor beating")
        assert alerts.sent[1] == ("resolve", "links beating again")
    finally:
        for proc in (process, locals().get("successor")):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()


def test_make_run_restarts_a_stopped_hang_watcher_through_the_supervisor(tmp_path):
    """fleet/run.py watches the watcher: its process stopped, it is killed and the supervisor starts another."""
    from fleet.run import restart_if_hung

    layout = Layout(tmp_path)
    layout.log_dir.mkdir()
    beating = [sys.executable, "-c", BEATER_FROM_ENV]
    listed = [Program("hangwatch", beating, autostart=True, hung=Bounds(0.3, 1.0))]
    layout.config.write_text(render_config(listed, layout, BASE_DIR))
    supervisord = start_supervisord(layout, dict(os.environ))
    try:
        assert wait_for_rpc(layout, supervisord) is not None
        wait_for(lambda: layout.beat("hangwatch").exists(), 30, "the first beat")
        first = rpc(layout).supervisor.getProcessInfo("fleet:hangwatch")["pid"]
        restart_if_hung(layout, "hangwatch", Bounds(0.3, 1.0))
        assert alive(first)  # beating: left alone
        os.kill(first, signal.SIGSTOP)
        wait_for(
            lambda: restart_if_hung(layout, "hangwatch", Bounds(0.3, 1.0)) or not alive(first), 10, "killed"
        )
        wait_for(
            lambda: rpc(layout).supervisor.getProcessInfo("fleet:hangwatch")["pid"] not in (0, first),
            30,
            "again",
        )
    finally:
        supervisord.terminate()
        supervisord.wait(30)


# ----- the embedded Redis's append-only file -----


def test_the_embedded_redis_rewrites_its_append_only_file_before_it_grows_past_its_bound(tmp_path):
    import redis

    from fleet.embedded_redis import AOF_REWRITE_MIN, server_command

    command = server_command(tmp_path / "redis.sock", keep_data=True)
    assert command[command.index("--auto-aof-rewrite-min-size") + 1] == AOF_REWRITE_MIN
    server = subprocess.Popen(command, stdout=subprocess.DEVNULL)
    try:
        wait_for(lambda: (tmp_path / "redis.sock").exists(), 10, "redis listening")
        client = redis.Redis(unix_socket_path=str(tmp_path / "redis.sock"))
        client.config_set(
            "auto-aof-rewrite-min-size", 1024 * 1024
        )  # the same rule, with a bound a test can reach
        for _ in range(100):  # 6 MB written over one key: the data stays 64 kB
            client.set("pose", os.urandom(64 * 1024))
        aof = tmp_path / "appendonly.aof"

        def rewritten() -> (
            bool
        ):  # started on its own (finishing it is Redis's business, slow on a loaded host)
            info = client.info("persistence")
            return info["aof_rewrite_in_progress"] == 1 or info["aof_last_rewrite_time_sec"] >= 0

        # without a rewrite the file would hold all 6.4 MB written and Redis would never fork to shrink it
        wait_for(rewritten, 10, f"{aof} rewritten past its bound: {client.info('persistence')}")
        assert client.get("pose") is not None
    finally:
        server.terminate()
        server.wait(10)
