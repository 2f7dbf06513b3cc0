"""An executor process killed mid-instruction: the scheduler process stops the robot within 2 s and fails the
instruction ("executor lost") within 10 s; another executor process takes the robot over for what comes next.

The robot here has no command timeout (as many real robots do not): without the watchdog's zero it would
drive on with the last Twist it got.
"""

import math
import os
import signal
import subprocess
import sys
import time

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

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow]
AT_REST_S, FINAL_S = 2.0, 10.0  # issue 14: robot at rest, instruction final, after its executor is lost
TAKE_OVER_S = (
    10.0  # a robot whose executor died is run by another within this (its lock and membership lapse)
)


def subprocess_env() -> dict:
    """What a fleet process needs to share the test's database, Redis and keys (fleet.processes)."""
    try:
        return processes.fleet_env()
    except ValueError as exc:  # an in-memory test database
        pytest.skip(f"an executor process cannot share the test database: {exc}")


def start_executor() -> subprocess.Popen:
    return processes.start([sys.executable, "manage.py", "executor"], subprocess_env())


@pytest.fixture
def executor_process(turtle_sim):
    """`manage.py executor` as `make run` starts it, sharing the test database and Redis."""
    proc = start_executor()
    try:
        yield proc
    finally:
        processes.end(proc)


@pytest.fixture
def scheduler_process(turtle_sim):
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


def test_killed_executor_leaves_the_robot_at_rest_and_the_instruction_failed(
    turtle_sim, executor_process, scheduler_process, fleet_admin
):
    """The executor process is killed: only the scheduler process is left to stop the robot."""
    sim = turtle_sim
    instruction, execution = start_moving(sim, fleet_admin)
    route = traffic_state.routes([execution.robot_id])[execution.robot_id]["path"]
    assert route  # its route is reserved while it drives
    os.killpg(executor_process.pid, signal.SIGKILL)
    killed_at = sim.call(lambda: sim.fleet.physics.time)
    killed = time.monotonic()

    wait_for(lambda: at_rest_after(sim, "turtlebot", killed_at), timeout=AT_REST_S, what="the robot at rest")
    assert wait_final(instruction, timeout=FINAL_S - (time.monotonic() - killed)).status == "failed"
    execution.refresh_from_db()
    # its process's presence dropped with its socket: found gone, not at its lock's lapse
    assert (execution.status, execution.error) == ("failed", watchdog.GONE)
    assert "executor lost" in Instruction.objects.get(pk=instruction.pk).outcome
    assert transitions("turtlebot")[-1][:3] == ("motion", "ready", watchdog.GONE)
    lost = Alert.objects.open().filter(kind="executor_lost")
    wait_for(lost.exists, timeout=5, what="the executor_lost alert (raised after the settle)")
    assert lost.get().robot.name == "turtlebot" and f"#{instruction.pk}" in lost.get().message
    assert (
        traffic_state.routes([execution.robot_id]) == {}
    )  # nobody renews its route: dropped, not left to lapse
    parked = sim.pose("turtlebot")
    wait_for(lambda: sim.call(lambda: sim.fleet.physics.time) > killed_at + 4.0, timeout=10, what="a while")
    assert math.dist(sim.pose("turtlebot")[:2], parked[:2]) < 0.01  # and it stays at rest


def test_a_frozen_executor_is_found_lost_when_its_lock_lapses(
    turtle_sim, executor_process, scheduler_process, fleet_admin
):
    """SIGSTOP keeps the process's sockets, so its presence: its lock, no longer renewed, lapses instead, and the
    robot is stopped all the same."""
    sim = turtle_sim
    instruction, execution = start_moving(sim, fleet_admin)
    os.killpg(executor_process.pid, signal.SIGSTOP)
    try:
        frozen_at = sim.call(lambda: sim.fleet.physics.time)
        wait_for(
            lambda: at_rest_after(sim, "turtlebot", frozen_at), timeout=AT_REST_S, what="the robot at rest"
        )
        assert wait_final(instruction, timeout=FINAL_S).status == "failed"
        execution.refresh_from_db()
        assert (execution.status, execution.error) == ("failed", watchdog.LOST)
    finally:
        os.killpg(executor_process.pid, signal.SIGKILL)


def test_an_executor_that_only_lost_its_presence_stops_its_robot_too(
    turtle_sim, executor_process, scheduler_process, fleet_admin
):
    """The process alive, its presence connection cut (CLIENT KILL of just that one): the watchdog takes it as
    gone and releases its lock, and its runner, told at its next renewal that the lock is not its own, stops
    too. The robot ends at rest and stays there: nothing drives on under an execution recorded as failed."""
    sim = turtle_sim
    instruction, execution = start_moving(sim, fleet_admin)
    redis_ = coordination.connection()
    name = coordination.presence_channel(coordination.holder_process(execution.worker))
    cut = [client["id"] for client in redis_.client_list() if client.get("name") == name]
    assert len(cut) == 1, redis_.client_list()
    redis_.client_kill_filter(_id=cut[0])
    cut_at = sim.call(lambda: sim.fleet.physics.time)

    wait_for(lambda: at_rest_after(sim, "turtlebot", cut_at), timeout=AT_REST_S, what="the robot at rest")
    assert wait_final(instruction, timeout=FINAL_S).status == "failed"
    execution.refresh_from_db()
    assert (execution.status, execution.error) == ("failed", watchdog.GONE)
    # the runner learns its lock is gone at its next renewal (HEARTBEAT_S) and may send one command more before
    # its own zero (CI 2026-11-29: 0.038 m after the watchdog's zero): at rest from then on
    settled_at = sim.call(lambda: sim.fleet.physics.time) + 1.0
    wait_for(
        lambda: sim.call(lambda: sim.fleet.physics.time) > settled_at, timeout=10, what="the runner's renewal"
    )
    wait_for(lambda: at_rest(sim, "turtlebot"), timeout=AT_REST_S, what="the robot at rest after its runner")
    parked = sim.pose("turtlebot")
    wait_for(lambda: sim.call(lambda: sim.fleet.physics.time) > settled_at + 4.0, timeout=10, what="a while")
    assert math.dist(sim.pose("turtlebot")[:2], parked[:2]) < 0.01  # and it stays at rest
    assert executor_process.poll() is None  # the process lived through it


def test_another_executor_takes_over_the_robot_of_one_killed(
    turtle_sim, executor_process, scheduler_process, fleet_admin
):
    """Two executor processes: the one running the robot is killed; the robot is stopped, its instruction fails
    once, and the next instruction for it runs on the other process (rendezvous over the live members, through
    the robot's lock)."""
    sim = turtle_sim
    other = start_executor()
    try:
        instruction, execution = start_moving(sim, fleet_admin)
        runner_pid = int(execution.worker.split(":")[1])  # the executor process holding the robot's lock
        assert runner_pid in (executor_process.pid, other.pid)
        survivor = other if runner_pid == executor_process.pid else executor_process
        os.killpg(runner_pid, signal.SIGKILL)
        killed_at = sim.call(lambda: sim.fleet.physics.time)
        wait_for(
            lambda: at_rest_after(sim, "turtlebot", killed_at), timeout=AT_REST_S, what="the robot at rest"
        )
        assert wait_final(instruction, timeout=FINAL_S).status == "failed"

        start = sim.pose("turtlebot")
        goal = (start[0] + 0.5, start[1])
        again = submit("move turtlebot on", fleet_admin, parse=parse(step(["turtlebot"], *goal, "on")))
        assert wait_final(again, timeout=TAKE_OVER_S + 40).status == "succeeded", again.outcome
        taken = Execution.objects.get(instruction=again)
        assert int(taken.worker.split(":")[1]) == survivor.pid  # run by the process left
        assert math.dist(sim.pose("turtlebot")[:2], goal) < 0.25  # and the robot did go there
        assert (
            Execution.objects.get(pk=execution.pk).status == "failed"
        )  # the first one failed once, for good
        assert Alert.objects.open().filter(kind="executor_lost").count() == 1
        released = lambda: coordination.lock_holders([execution.robot_id])[execution.robot_id] is None  # noqa: E731
        wait_for(released, timeout=5, what="the survivor's drain done, its lock released")
    finally:
        processes.end(other)
