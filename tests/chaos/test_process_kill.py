"""kill -9 of each process of `make run`, one at a time, while the turtlebot drives an instruction: the rest keeps
serving, the process comes back, the robot is at rest and the instruction final.

One `make run` for the module (tests in file order: the embedded Redis last, then Ctrl-C). The simulator runs
with `--keep-last-command`: its robots drive on with their last velocity for ever, as bases without a cmd_vel
timeout do, so a robot at rest after a fault is the portal's doing. The robot is judged by its own odometry,
read from its endpoint (tests/chaos/system.py, Odometry), not by what the portal says. Each fault records what
it cost (docs/fault-survival.md; printed at the end of the run, and written to FLEET_CHAOS_OUT if set).
"""

from __future__ import annotations

import math
import socket
import sqlite3
import time
import urllib.error
from collections.abc import Callable
from dataclasses import dataclass

import pytest
import redis
from redis.backoff import NoBackoff
from redis.retry import Retry

from execution.models import Instruction
from fleet.supervision import START_SECONDS
from tests.chaos.system import Odometry, Requests, RunningSystem, alive, send_frames

pytestmark = [pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(300)]

# In an order that keeps every drive short (under 2 m): the turtlebot leaves its start pose on the first and the
# last fault, which stop it on the way.
FAULTS = ["executor-1", "web", "worker", "control", "links", "scheduler", "sim", "redis"]
BACK_WITHIN = 10.0  # s: the supervisor has started the killed process again under a new pid
UP_WITHIN = 60.0  # s: ... and it stayed up START_SECONDS (generous: the machine may be busy)
AT_REST_WITHIN, FINAL_WITHIN = 2.0, 10.0  # s after the fault (issue 14)
MOVING_WITHIN = 60.0  # s from submitting until the robot drives (interpreting on a busy 2-core machine)

# The faults that take the instruction's executor away, and the reason its failure gives. The executor process
# drives the robots (one asyncio task each); a killed simulator is the robot's endpoint killed and
# restarted (the robot comes back at its start pose, at rest); a killed Redis takes the executor's lock (its
# board cannot renew it), so the executor stops its robot itself. Every other process is not in the
# instruction's path: the robot drives on to its goal.
ENDS_IT = {"executor-1": "executor lost", "sim": "link lost", "redis": "executor lost"}

ROBOT, START = (
    "turtlebot",
    (-2.0, -0.5),
)  # its endpoint (port offset 1) and start pose (yaw 0) in the paper world
PLACES = {"I": (-1.0, 1.0), "H": (0.0, 1.0)}  # it drives between these, a metre apart (1.8 m from its start)
DRIVE_S = 10.0  # s: under 2 m at 0.22 m/s, and a turn
ARRIVED_WITHIN = 0.3  # m from the place: "arrived" (the controller's tolerance and then some)
FINAL = {str(status) for status in Instruction.FINAL}


@pytest.fixture(scope="module")
def odometry(system):
    """The turtlebot's odometry, straight from its simulated endpoint."""
    reader = Odometry(f"ws://127.0.0.1:{system.sim_port_base + 1}")
    yield reader
    reader.close()


@dataclass
class Work:
    """An instruction in flight: its id, where the robot is going, and when it was seen driving."""

    instruction: int
    place: str
    moving_at: float


def where(odometry: Odometry) -> tuple[float, float]:
    """The robot's position in the world, from its last odometry (which starts at its start pose, facing +x):
    its callers know it at rest, so a sample the reader took late still says where it is."""
    last = odometry.samples[-1] if odometry.samples else None
    assert last is not None, "no odometry from the turtlebot"
    return START[0] + last.x, START[1] + last.y


def put_to_work(system: RunningSystem, odometry: Odometry) -> Work:
    """Send the turtlebot, at rest with nothing open, to the nearer of two places it is not at; return once it
    drives."""
    system.wait_until(lambda: odometry.rested_since() is not None, 30, "the turtlebot at rest before")
    system.wait_until(lambda: not _open(system), 30, "no instruction open before")
    away = {name: math.dist(spot, where(odometry)) for name, spot in PLACES.items()}
    place = min((name for name in away if away[name] > 0.5), key=away.get)
    pk = system.instruct(f"move {ROBOT} to {place} very fast")
    system.wait_until(odometry.moving, MOVING_WITHIN, f"instruction #{pk} under way: {ROBOT} driving")
    return Work(pk, place, time.monotonic())


def _open(system: RunningSystem) -> list:
    return [row for row in system.instructions() if row[1] not in FINAL]


def _final(system: RunningSystem, work: Work) -> bool:
    try:
        return system.instruction(work.instruction)[0] in FINAL
    except sqlite3.OperationalError:
        return False  # the database busy: ask again


def assert_still_in_charge(
    system: RunningSystem, fault: str, work: Work, odometry: Odometry, killed: float, times: dict[str, float]
) -> None:
    """The execution's side of a fault: the robot at rest and the instruction final, as the fault demands.

    Faults in ENDS_IT: the robot at rest within AT_REST_WITHIN of the kill (by its odometry; with no cmd_vel
    timeout only a zero sent after the fault stops it; a killed simulator's robot at rest in every odometry message
    once its endpoint is back: how long the simulator takes to start is not the portal's) and
    the instruction failed, saying why, within FINAL_WITHIN. The others: the robot drove on after the kill and
    arrived, and the instruction succeeded within FINAL_WITHIN of its drive's time (DRIVE_S). Either way nothing
    is left open and the portal answers.
    """
    status, outcome = system.instruction(work.instruction)
    rest_s, final_s = times["at rest"], times["final"]
    if fault in ENDS_IT:
        assert status == "failed" and ENDS_IT[fault] in outcome, (status, outcome)
        if fault == "sim":  # its robot is gone with it: back, it is at rest from its first odometry on
            back = [sample for sample in odometry.samples if sample.at >= killed + times["serving"]]
            assert back and all(sample.still() for sample in back), (
                f"{ROBOT} moved after its simulator came back: {[(s.vx, s.wz) for s in back if not s.still()][:5]}"
            )
        else:
            assert rest_s <= AT_REST_WITHIN, f"{ROBOT} came to rest {rest_s:.1f} s after {fault} was killed"
    else:
        assert status == "succeeded", (status, outcome)
        assert odometry.travelled(killed) > 0.2, f"{ROBOT} did not drive on after {fault} was killed"
        assert math.dist(where(odometry), PLACES[work.place]) < ARRIVED_WITHIN, where(odometry)
        final_s -= DRIVE_S  # it was final when it got there: its drive's time is not the fault's
    assert final_s <= FINAL_WITHIN, f"instruction #{work.instruction} final {final_s:.1f} s after the fault"
    assert not _open(system), f"left open after {fault}: {_open(system)}"
    assert Requests(system).load() is None, f"after {fault} came back the portal does not answer"


def resting(odometry: Odometry, seen: dict, at: tuple[float, float] | None = None) -> Callable[[], bool]:
    """A condition for times_until: the robot at rest (at: within ARRIVED_WITHIN of that place; a route's
    waypoint has the robot settle for most of a second, a whole one on a loaded machine), the moment its rest
    began kept in seen["since"] (a later look may find no fresh sample: the reader late, CI 2026-11-29)."""

    def condition() -> bool:
        since = odometry.rested_since()
        if since is None or (at is not None and math.dist(where(odometry), at) >= ARRIVED_WITHIN):
            return False
        seen.setdefault("since", since)
        return True

    return condition


def serving(system: RunningSystem, fault: str) -> bool:
    """Whether the process does its work again, where that can be seen from outside."""
    return SERVING_PROBES.get(fault, lambda _system: True)(system)


def _portal_loads(system: RunningSystem) -> bool:
    try:
        return Requests(system).load() is None  # a new session: logging in is part of serving again
    except (OSError, urllib.error.URLError):
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
def test_a_process_killed_under_a_moving_robot_leaves_it_at_rest_or_arrived_and_comes_back(
    system, odometry, fault, figures
):
    others = {name: process.pid for name, process in system.processes().items() if name != fault}
    with Requests(system) as loads:
        time.sleep(1.0)  # a few page loads before the fault
        work = put_to_work(system, odometry)
        killed = time.monotonic()
        old_pid = system.kill(fault)
        new_pid_s, serving_s, up_s, final_s, _ = system.times_until(
            {
                f"{fault} under a new pid": lambda: system.processes()[fault].pid not in (0, old_pid),
                f"{fault} serving again": lambda: serving(system, fault),
                f"{fault} up again": lambda: system.back(fault, old_pid),
                f"instruction #{work.instruction} final": lambda: _final(system, work),
                f"{ROBOT} at rest": resting(
                    odometry, rest := {}, None if fault in ENDS_IT else PLACES[work.place]
                ),
            },
            UP_WITHIN,
            since=killed,
        )
        times = {"at rest": rest["since"] - killed, "final": final_s, "serving": serving_s}
        time.sleep(1.0)  # a few page loads after
    status, outcome = system.instruction(work.instruction)
    figures.append(
        {
            "fault (kill -9)": fault,
            "robot at rest (s)": f"{times['at rest']:.1f}",
            "instruction final (s)": f"{final_s:.1f}",
            "instruction": f"{status}: {outcome}",
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
    assert_still_in_charge(system, fault, work, odometry, killed, times)


# What a broken driver or bridge might put on a robot's odometry topic: frames whose message is no Odometry.
# The endpoint relays them (they are JSON objects) to every subscriber: the links process and the executor.
GARBAGE_MESSAGES = [
    {},
    {"pose": None, "twist": None},
    {"pose": {"pose": {"position": {"x": "north", "y": []}, "orientation": {}}}},
    {"header": 7, "pose": {"pose": "here"}, "twist": {"twist": [1, 2]}},
]
# ... and frames that are not rosbridge at all, or name no topic; the endpoint itself must shrug them off.
GARBAGE_FRAMES = ["\x00\xff not rosbridge", '{"op": "publish", "topic": ["x"], "msg": {}}', "[]", "{"]


def test_garbage_on_a_moving_robots_link_is_dropped_and_the_robot_arrives(system, odometry, figures):
    """Every process keeps running (no link reader dies of a frame), the robot arrives and rests."""
    pids = {name: process.pid for name, process in system.processes().items()}
    endpoint = f"ws://127.0.0.1:{system.sim_port_base + 1}"
    with Requests(system) as loads:
        time.sleep(1.0)
        work = put_to_work(system, odometry)
        started = time.monotonic()
        frames = [{"op": "publish", "topic": "/odom", "msg": msg} for msg in GARBAGE_MESSAGES * 5]
        sent = send_frames(
            endpoint, GARBAGE_FRAMES + frames
        )  # a second of garbage, interleaved with odometry
        final_s, _ = system.times_until(
            {
                f"instruction #{work.instruction} final": lambda: _final(system, work),
                f"{ROBOT} at rest": resting(odometry, rest := {}, PLACES[work.place]),
            },
            UP_WITHIN,
            since=started,
        )
        rest_s = rest["since"] - started
    status, outcome = system.instruction(work.instruction)
    figures.append(
        {
            "fault (kill -9)": f"garbage on the robot's link ({sent} frames)",
            "robot at rest (s)": f"{rest_s:.1f}",
            "instruction final (s)": f"{final_s:.1f}",
            "instruction": f"{status}: {outcome}",
            "new pid (s)": "–",
            f"up {START_SECONDS} s (s)": "–",
            "serving again (s)": "–",
            "page loads failed / sent": f"{len(loads.failed)} / {loads.sent}",
        }
    )
    assert {name: process.pid for name, process in system.processes().items()} == pids
    assert status == "succeeded", (status, outcome)
    assert math.dist(where(odometry), PLACES[work.place]) < ARRIVED_WITHIN, where(odometry)
    assert not loads.failed, loads.failed
    assert not _open(system)


def test_the_embedded_redis_keeps_its_data_across_a_kill(system):
    queue = _redis(system)
    queue.rpush("chaos:queued", "work that was waiting")
    time.sleep(1.5)  # the append-only file is written to disk every second
    old_pid = system.kill("redis")
    system.wait_until(lambda: system.back("redis", old_pid), UP_WITHIN, "redis up again")
    system.wait_until(lambda: _redis_answers(system), UP_WITHIN, "redis answering (its data loaded)")
    assert queue.lrange("chaos:queued", 0, -1) == [b"work that was waiting"]


def test_ctrl_c_stops_everything_and_make_run_exits_0(system):
    pids = [process.pid for process in system.processes().values()]
    status = system.interrupt()
    assert status == 0, system.text()[-3000:]
    assert "Error 130" not in system.text() and "Interrupt" not in system.text()
    assert not [pid for pid in pids if alive(pid)], "processes outlived make run"
    assert not _simulator_listens(system)
