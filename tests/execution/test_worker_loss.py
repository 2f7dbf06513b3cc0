"""An executor killed mid-instruction: the scheduler process stops the robot within 2 s and fails the
instruction ("executor lost") within 10 s; the redelivered task runs nothing twice.

The robot here has no command timeout (as many real robots do not): without the watchdog's zero it would
drive on with the last Twist it got.
"""

import math
import os
import signal
import sys
import time
import uuid

import pytest

from alerts.models import Alert
from execution import coordination, traffic_state, watchdog
from execution.instructions import submit
from execution.models import Execution, Instruction
from fleet import processes
from tests.execution.helpers import (
    at_rest,
    parse,
    step,
    transitions,
    wait_final,
    wait_for,
    without_command_timeout,
)

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]
AT_REST_S, FINAL_S = 2.0, 10.0  # issue 14: robot at rest, instruction final, after its executor is lost


def subprocess_env() -> dict:
    """What a fleet process needs to share the test's database, Redis and keys (fleet.processes)."""
    try:
        return processes.fleet_env()
    except ValueError as exc:  # an in-memory test database
        pytest.skip(f"a worker process cannot share the test database: {exc}")


@pytest.fixture
def celery_worker(turtle_world, settings):
    """A real Celery worker (prefork, one child) on a queue of its own, sharing the test database and Redis."""
    queue = f"exec-test-{uuid.uuid4().hex[:8]}"
    settings.FLEET_EXECUTE, settings.FLEET_EXECUTE_QUEUE = "celery", queue
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
    proc = processes.start(command, subprocess_env())
    try:
        yield proc
    finally:
        processes.end(proc)


@pytest.fixture
def scheduler_process(turtle_world, settings):
    """`manage.py scheduler` as `make run` starts it: the process that stays up and watches the executors."""
    proc = processes.start([sys.executable, "manage.py", "scheduler"], subprocess_env())
    try:
        yield proc
    finally:
        processes.end(proc)


def at_rest_after(sim, name: str, moment: float) -> bool:
    """At rest on a zero command published after `moment` (simulated time)."""
    return at_rest(sim, name) and sim.call(lambda: sim.fleet.robots[name].body.cmd.stamp > moment)


def start_moving(sim, user) -> tuple[Instruction, Execution]:
    """Send the turtlebot (without command timeout) far, and wait until it drives."""
    without_command_timeout(sim, "turtlebot")
    instruction = submit("move turtlebot far", user, parse=parse(step(["turtlebot"], 0.5, -0.5, "far")))
    wait_for(lambda: Instruction.objects.get(pk=instruction.pk).motion_started_at, timeout=40, what="motion")
    execution = Execution.objects.get(instruction=instruction)
    assert execution.status == "running"
    return instruction, execution


def test_killed_worker_leaves_the_robot_at_rest_and_the_instruction_failed(
    turtle_world, celery_worker, scheduler_process, fleet_admin
):
    """The whole worker (parent and pool) is killed: only the scheduler process is left to stop the robot."""
    sim = turtle_world
    instruction, execution = start_moving(sim, fleet_admin)
    route = traffic_state.routes([execution.robot_id])[execution.robot_id]["path"]
    assert route  # its route is reserved while it drives
    os.killpg(celery_worker.pid, signal.SIGKILL)
    killed_at = sim.call(lambda: sim.fleet.physics.time)
    killed = time.monotonic()

    wait_for(lambda: at_rest_after(sim, "turtlebot", killed_at), timeout=AT_REST_S, what="the robot at rest")
    assert wait_final(instruction, timeout=FINAL_S - (time.monotonic() - killed)).status == "failed"
    execution.refresh_from_db()
    assert (execution.status, execution.error) == ("failed", watchdog.LOST)
    assert "executor lost" in Instruction.objects.get(pk=instruction.pk).outcome
    assert transitions("turtlebot")[-1][:3] == ("motion", "ready", watchdog.LOST)
    lost = Alert.objects.open().filter(kind="executor_lost")
    wait_for(lost.exists, timeout=5, what="the executor_lost alert (raised after the settle)")
    assert lost.get().robot.name == "turtlebot" and f"#{instruction.pk}" in lost.get().message
    assert (
        traffic_state.routes([execution.robot_id]) == {}
    )  # nobody renews its route: dropped, not left to lapse
    parked = sim.pose("turtlebot")
    wait_for(lambda: sim.call(lambda: sim.fleet.physics.time) > killed_at + 4.0, timeout=10, what="a while")
    assert math.dist(sim.pose("turtlebot")[:2], parked[:2]) < 0.01  # and it stays at rest


def test_killed_pool_process_is_failed_once_and_its_redelivery_runs_nothing_twice(
    turtle_world, celery_worker, scheduler_process, fleet_admin
):
    """Only the pool process dies: its parent requeues the task (acks_late, reject_on_worker_lost)."""
    sim = turtle_world
    instruction, execution = start_moving(sim, fleet_admin)
    child_pid = int(execution.worker.split(":")[1])  # the pool process running the task
    assert child_pid != celery_worker.pid
    os.kill(child_pid, signal.SIGKILL)
    killed_at = sim.call(lambda: sim.fleet.physics.time)
    killed = time.monotonic()

    wait_for(lambda: at_rest_after(sim, "turtlebot", killed_at), timeout=AT_REST_S, what="the robot at rest")
    assert wait_final(instruction, timeout=FINAL_S - (time.monotonic() - killed)).status == "failed"
    parked = sim.pose("turtlebot")
    wait_for(
        lambda: sim.call(lambda: sim.fleet.physics.time) > killed_at + 6.0, timeout=15, what="redelivery"
    )
    assert Execution.objects.get(pk=execution.pk).status == "failed"
    assert [t for t in transitions("turtlebot") if t[1] == "motion"] == [transitions("turtlebot")[1]]
    assert math.dist(sim.pose("turtlebot")[:2], parked[:2]) < 0.01
    assert coordination.lock_holders([execution.robot_id])[execution.robot_id] is None
    assert Alert.objects.open().filter(kind="executor_lost").count() == 1
