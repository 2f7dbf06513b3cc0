"""kill -9 of each process of `make run`, one at a time: the rest keeps serving and the process comes back.

One `make run` for the module (tests in file order: the embedded Redis last, then Ctrl-C). Each fault records what
it cost (README "Fault survival"; the table is printed at the end of the run).
"""

from __future__ import annotations

import socket
import time

import pytest
import redis
from redis.backoff import NoBackoff
from redis.retry import Retry

from fleet.supervision import START_SECONDS
from tests.chaos.system import Requests, RunningSystem, alive

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

FAULTS = ["web", "worker", "control", "sim", "links", "scheduler", "redis"]
BACK_WITHIN = 10.0  # s: the supervisor has started the killed process again under a new pid
UP_WITHIN = 60.0  # s: ... and it stayed up START_SECONDS (generous: the machine may be busy)


def put_to_work(system: RunningSystem) -> object | None:
    """What the system is doing when the fault strikes. Nothing yet.

    The lead adds here an instruction in flight (a robot moving) and returns what assert_still_in_charge needs to
    judge it, e.g. the instruction's id and the robot's name.
    """
    return None


def assert_still_in_charge(system: RunningSystem, fault: str, work: object | None) -> None:
    """What must hold once the killed process is back, beyond the process itself: the portal answers.

    The lead adds here the execution's checks on `work`: the robot that was moving is at rest within 2 s (by its
    odometry) and the instruction is final within 10 s.
    """
    assert Requests(system).load() is None, f"after {fault} came back the portal does not answer"


def serving(system: RunningSystem, fault: str) -> bool:
    """Whether the process does its work again, where that can be seen from outside."""
    return SERVING_PROBES.get(fault, lambda _system: True)(system)


def _portal_loads(system: RunningSystem) -> bool:
    try:
        return Requests(system).load() is None  # a new session: logging in is part of serving again
    except OSError:
        return False


def _redis(system: RunningSystem) -> redis.Redis:
    """A client of the embedded Redis that fails at once (redis-py's default retries take seconds)."""
    return redis.Redis(
        unix_socket_path=str(system.var_dir / "redis.sock"), socket_timeout=2, retry=Retry(NoBackoff(), 0)
    )


def _redis_answers(system: RunningSystem) -> bool:
    try:
        return _redis(system).ping()
    except redis.RedisError:
        return False


def _simulator_listens(system: RunningSystem) -> bool:
    try:
        socket.create_connection(("127.0.0.1", system.sim_port_base), timeout=1).close()
    except OSError:
        return False
    return True


SERVING_PROBES = {"web": _portal_loads, "redis": _redis_answers, "sim": _simulator_listens}


@pytest.mark.parametrize("fault", FAULTS)
def test_a_killed_process_is_started_again_and_the_portal_keeps_answering(system, fault, figures):
    work = put_to_work(system)
    others = {name: process.pid for name, process in system.processes().items() if name != fault}
    with Requests(system) as loads:
        time.sleep(1.0)  # a few page loads before the fault
        old_pid = system.kill(fault)
        new_pid_s, serving_s, up_s = system.times_until(
            {
                f"{fault} under a new pid": lambda: system.processes()[fault].pid not in (0, old_pid),
                f"{fault} serving again": lambda: serving(system, fault),
                f"{fault} up again": lambda: system.back(fault, old_pid),
            },
            UP_WITHIN,
        )
        time.sleep(1.0)  # a few page loads after
    figures.append(
        {
            "fault (kill -9)": fault,
            "new pid (s)": f"{new_pid_s:.1f}",
            f"up {START_SECONDS} s (s)": f"{up_s:.1f}",
            "serving again (s)": f"{serving_s:.1f}" if fault in SERVING_PROBES else "–",
            "page loads failed / sent": f"{len(loads.failed)} / {loads.sent}",
        }
    )
    assert new_pid_s <= BACK_WITHIN, f"{fault} took {new_pid_s:.1f} s to be started again"
    if fault != "web":
        assert not loads.failed, f"page loads failed while {fault} was down: {loads.failed}"
    now = system.processes()
    assert {name: now[name].pid for name in others} == others, (
        f"others died with {fault} (e.g. not reconnecting)"
    )
    assert_still_in_charge(system, fault, work)


def test_the_embedded_redis_keeps_its_data_across_a_kill(system):
    queue = _redis(system)
    queue.rpush("chaos:queued", "work that was waiting")
    time.sleep(1.5)  # the append-only file is written to disk every second
    old_pid = system.kill("redis")
    system.wait_until(lambda: system.back("redis", old_pid), UP_WITHIN, "redis up again")
    assert queue.lrange("chaos:queued", 0, -1) == [b"work that was waiting"]


def test_ctrl_c_stops_everything_and_make_run_exits_0(system):
    pids = [process.pid for process in system.processes().values()]
    status = system.interrupt()
    assert status == 0, system.text()[-3000:]
    assert "Error 130" not in system.text() and "Interrupt" not in system.text()
    assert not [pid for pid in pids if alive(pid)], "processes outlived make run"
    assert not _simulator_listens(system)
