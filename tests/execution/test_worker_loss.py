"""A Celery worker killed mid-instruction: the robot is stopped, the instruction failed, never run twice."""

import os
import signal
import subprocess
import sys
import uuid
from pathlib import Path

import pytest
from django.db import connection

from execution import coordination, watchdog
from execution.instructions import submit
from execution.models import Execution, Instruction
from tests.execution.helpers import parse, step, transitions, wait_final, wait_for

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[2]


def database_url() -> str:
    """The test database as a DATABASE_URL the worker subprocess can open."""
    s = connection.settings_dict
    if s["ENGINE"].endswith("sqlite3"):
        if "memory" in str(s["NAME"]):
            pytest.skip("the test database is in memory; a worker process cannot share it")
        return f"sqlite:///{s['NAME']}"
    return f"postgres://{s['USER']}:{s['PASSWORD'] or ''}@{s['HOST'] or '127.0.0.1'}:{s['PORT'] or 5432}/{s['NAME']}"


@pytest.fixture
def celery_worker(turtle_world, settings):
    """A real Celery worker (prefork, one child) on a queue of its own, sharing the test database and Redis."""
    queue = f"exec-test-{uuid.uuid4().hex[:8]}"
    settings.FLEET_EXECUTE, settings.FLEET_EXECUTE_QUEUE = "celery", queue
    env = {
        **os.environ,
        "DATABASE_URL": database_url(),
        "REDIS_URL": settings.REDIS_URL,
        "FLEET_EXEC_KEY_PREFIX": settings.FLEET_EXEC_KEY_PREFIX,
        "DJANGO_SETTINGS_MODULE": "fleet.settings",
    }
    command = [
        sys.executable,
        "-m",
        "celery",
        "-A",
        "fleet",
        "worker",
        "-Q",
        queue,
        "-c",
        "1",
        "-l",
        "warning",
    ]
    proc = subprocess.Popen(command, cwd=ROOT, env=env, start_new_session=True)
    try:
        yield proc
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_killed_worker_leaves_the_robot_stopped_and_the_instruction_failed(
    turtle_world, celery_worker, fleet_admin
):
    sim = turtle_world
    instruction = submit(
        "move turtlebot far", fleet_admin, parse=parse(step(["turtlebot"], 0.5, -0.5, "far"))
    )
    wait_for(lambda: Instruction.objects.get(pk=instruction.pk).motion_started_at, timeout=40, what="motion")
    execution = Execution.objects.get(instruction=instruction)
    assert execution.status == "running"
    child_pid = int(execution.worker.split(":")[1])  # the pool process running the task
    assert child_pid != celery_worker.pid
    os.kill(child_pid, signal.SIGKILL)
    killed_at = sim.call(lambda: sim.fleet.physics.time)

    robot_id = execution.robot_id
    wait_for(lambda: coordination.lock_holder(robot_id) is None, timeout=10, what="the lock to expire")
    assert watchdog.recover() == [execution.pk]  # what the scheduler loop does every half second

    execution.refresh_from_db()
    assert (execution.status, execution.error) == ("failed", watchdog.LOST)
    assert wait_final(instruction).status == "failed"
    command = sim.call(lambda: sim.fleet.robots["turtlebot"].body.cmd)
    assert (command.vx, command.wz) == (0.0, 0.0) and command.stamp > killed_at  # the watchdog's zero
    assert transitions("turtlebot")[-1][:3] == ("motion", "ready", watchdog.LOST)

    # The worker's parent requeued the task (acks_late, reject_on_worker_lost): its redelivery runs nothing twice.
    parked = sim.pose("turtlebot")
    wait_for(
        lambda: sim.call(lambda: sim.fleet.physics.time) > killed_at + 6.0, timeout=15, what="redelivery"
    )
    assert Execution.objects.get(pk=execution.pk).status == "failed"
    assert [t for t in transitions("turtlebot") if t[1] == "motion"] == [transitions("turtlebot")[1]]
    assert abs(sim.pose("turtlebot")[0] - parked[0]) < 0.01
