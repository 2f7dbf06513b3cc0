"""Redis killed while a Celery worker runs a task: the worker reconnects once Redis is back, instead of exiting.

Celery/kombu 5.7.0 ended such a worker with `Unrecoverable error: AttributeError("'NoneType' object has no
attribute 'hostname'")`; fleet/celery.py's Redis transport turns that into a connection error Celery recovers from.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from celery import Celery

from fleet import embedded_redis
from fleet.env import celery_broker_url

pytestmark = [pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(180)]

BASE_DIR = Path(__file__).resolve().parents[2]
WAIT = 60.0  # s for a worker to start, or to take a task once Redis is back (a busy machine)


def wait_for(condition, what: str, timeout: float = WAIT) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"not within {timeout:g} s: {what}"
        time.sleep(0.1)


@pytest.fixture
def broker(tmp_path):
    """A Redis of our own on a unix socket; `broker.restart()` after a kill -9."""

    class Broker:
        socket = tmp_path / "redis.sock"
        url = f"unix://{socket}"
        process = embedded_redis.start(socket)

        def kill(self) -> None:
            self.process.kill()
            self.process.wait()

        def restart(self) -> None:
            self.process = embedded_redis.start(self.socket)

    running = Broker()
    yield running
    embedded_redis.stop(running.process, running.socket)


@pytest.fixture
def worker(broker, tmp_path):
    """A threads worker of the fleet's app on queue `chaos`, with its log."""
    log = tmp_path / "worker.log"
    env = {
        key: value for key, value in os.environ.items() if key not in {"DATABASE_URL", "FLEET_REDIS_PREFIX"}
    }
    env |= {"REDIS_URL": broker.url, "FLEET_VAR_DIR": str(tmp_path), "PYTHONUNBUFFERED": "1"}
    command = [sys.executable, "-m", "celery", "-A", "tests.chaos.celery_app", "worker"]
    command += ["-Q", "chaos", "-P", "threads", "-c", "2", "-l", "info", "--without-mingle"]
    with open(log, "wb") as out:
        process = subprocess.Popen(command, cwd=BASE_DIR, env=env, stdout=out, stderr=subprocess.STDOUT)
    process.log = log
    wait_for(lambda: b" ready." in log.read_bytes() or process.poll() is not None, "the worker ready")
    yield process
    process.terminate()
    try:
        process.wait(timeout=20)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def send_hold(broker, seconds: float, marks: Path) -> None:
    """Queue the hold task, as the portal queues an instruction."""
    marks.mkdir()
    client = Celery(broker=celery_broker_url(broker.url))
    client.send_task("tests.chaos.hold", args=[seconds, str(marks)], queue="chaos")
    client.close()


def test_a_worker_survives_redis_killed_under_a_running_task(broker, worker, tmp_path):
    first = tmp_path / "first"
    send_hold(broker, 4.0, first)
    wait_for(lambda: (first / "started").exists(), "the first task started")
    broker.kill()  # while the task runs, its message taken and not yet acknowledged
    wait_for(lambda: (first / "ended").exists(), "the first task ended, Redis still gone")
    broker.restart()

    second = tmp_path / "second"
    send_hold(broker, 0.0, second)
    wait_for(
        lambda: (second / "ended").exists() or worker.poll() is not None, "a task taken after Redis came back"
    )

    log = worker.log.read_text()
    assert worker.poll() is None, f"the worker exited:\n{log[-3000:]}"
    assert "Unrecoverable error" not in log
    assert (second / "ended").exists()
