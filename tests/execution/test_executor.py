"""The executor processes' shell (execution/executor.py), against the real Redis, with fake drains: robots split
by rendezvous, a wake-up reaching the owner only, the sweep, fail-over from a killed member, a clean stop, and a
Redis connection cut and restored."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import threading
import time
import uuid
from urllib.parse import urlparse

import pytest
import redis

from execution import coordination, executor
from execution.executor import Executor, in_thread, owner, wake
from execution.models import Execution, Instruction
from robots.models import Robot
from tests.execution.helpers import wait_for

# the sweep's queries run in a thread of the executor's: it must see the test's rows (committed)
pytestmark = pytest.mark.django_db(transaction=True)

IDS = range(1, 101)
TAKE_OVER_S = executor.MEMBER_TTL_MS / 1000 + 2 * executor.SWEEP_S + 3  # a member's lapse, a sweep, and slack


@pytest.fixture(autouse=True)
def keys(settings):
    """Redis keys (membership, wake channel, locks) of this test's own."""
    settings.FLEET_EXEC_KEY_PREFIX = f"test:executor:{uuid.uuid4().hex[:8]}"


class Drains:
    """Fake drains: each records (executor, robot) when it starts, holds `hold` seconds, and records its return
    or its cancel."""

    def __init__(self, hold: float = 0.0) -> None:
        self.hold = hold
        self.started: list[tuple[str, int]] = []
        self.returned: list[tuple[str, int]] = []
        self.cancelled: list[tuple[str, int]] = []

    def of(self, name: str):
        async def drain(robot_id: int) -> bool:
            self.started.append((name, robot_id))
            try:
                await asyncio.sleep(self.hold)
            except asyncio.CancelledError:
                self.cancelled.append((name, robot_id))
                raise
            self.returned.append((name, robot_id))
            return True

        return drain

    def robots(self, name: str, since: int = 0) -> set[int]:
        return {robot_id for who, robot_id in self.started[since:] if who == name}


def split(executors: list[Executor], ids=IDS) -> dict[int, str] | None:
    """{robot: its one owner} once every executor sees the same members, else None."""
    owners = {robot_id: [e.name for e in executors if e.owns(robot_id)] for robot_id in ids}
    if any(len(names) != 1 for names in owners.values()):
        return None
    return {robot_id: names[0] for robot_id, names in owners.items()}


def waiting_robots(count: int, status: str = "queued") -> list[int]:
    """Robots each with one execution in this status (never woken)."""
    ids = []
    for _ in range(count):
        robot = Robot.objects.create(name=f"r{uuid.uuid4().hex[:6]}", endpoint=f"ws://sim/{uuid.uuid4().hex}")
        instruction = Instruction.objects.create(text=f"move {robot.name} to A", status="queued")
        Execution.objects.create(
            instruction=instruction, robot=robot, status=status, steps=[{"action": "move"}]
        )
        ids.append(robot.pk)
    return ids


def test_two_executors_split_the_robots_by_rendezvous_stably():
    drains = Drains()
    with in_thread(name="a", drain=drains.of("a")) as a, in_thread(name="b", drain=drains.of("b")) as b:
        owners = wait_for(lambda: split([a, b]), timeout=5, what="both executors to see each other")
        assert owners == {robot_id: owner(robot_id, ["a", "b"]) for robot_id in IDS}
        shares = [sum(name == who for name in owners.values()) for who in "ab"]
        assert min(shares) >= 30, shares  # both have robots, neither has nearly all
        time.sleep(4 * executor.RENEW_S)  # several renewals later: the same split
        assert split([a, b]) == owners
    assert drains.started == []  # nothing woken, nothing waiting: no drain ran


def test_a_member_that_leaves_moves_only_its_own_robots():
    drains = Drains()
    with contextlib.ExitStack() as stack:
        a, b = (stack.enter_context(in_thread(name=name, drain=drains.of(name))) for name in "ab")
        with in_thread(name="c", drain=drains.of("c")) as c:
            before = wait_for(lambda: split([a, b, c]), timeout=5, what="three executors to see each other")
        after = wait_for(lambda: split([a, b]), timeout=5, what="the two left to see c gone")
    moved = {robot_id for robot_id in IDS if before[robot_id] != after[robot_id]}
    assert moved == {robot_id for robot_id in IDS if before[robot_id] == "c"} != set()
    assert after == {robot_id: owner(robot_id, ["a", "b"]) for robot_id in IDS}


def test_a_wake_starts_one_task_per_robot_on_its_owner_only_even_when_woken_twice():
    drains = Drains(hold=1.0)
    with in_thread(name="a", drain=drains.of("a")) as a, in_thread(name="b", drain=drains.of("b")) as b:
        owners = wait_for(lambda: split([a, b]), timeout=5, what="both executors to see each other")
        robots = list(range(1, 11))
        assert {owners[robot_id] for robot_id in robots} == {"a", "b"}
        wake(robots)
        wait_for(lambda: len(drains.started) == len(robots), timeout=5, what="every robot's drain")
        wake(robots)  # while every drain still runs: no second task
        time.sleep(0.3)
        assert sorted(drains.started) == sorted((owners[robot_id], robot_id) for robot_id in robots)
        # a drain that returned is forgotten: the next wake-up starts the robot again
        wait_for(lambda: len(drains.returned) == len(robots), timeout=5, what="the drains to return")
        wake(robots[:1])
        wait_for(lambda: len(drains.started) == len(robots) + 1, timeout=5, what="the robot started again")
        assert drains.started[-1] == (owners[1], 1)


def test_the_sweep_starts_robots_with_waiting_work_that_were_never_woken():
    queued, preempted = waiting_robots(1), waiting_robots(1, status="preempted")
    finished, locked = waiting_robots(1, status="succeeded"), waiting_robots(1)
    lock = coordination.RobotLock(locked[0], token="someone else", ttl_ms=30_000)
    assert lock.acquire()
    drains = Drains()
    with in_thread(name="a", drain=drains.of("a")):
        wait_for(lambda: drains.robots("a") >= {*queued, *preempted}, timeout=5, what="the sweep")
        time.sleep(2 * executor.SWEEP_S)  # more sweeps: neither a finished robot nor a locked one
        assert drains.robots("a") == {*queued, *preempted}
        assert finished[0] not in drains.robots("a") and locked[0] not in drains.robots("a")
        lock.release()  # its runner is done: the sweep starts it
        wait_for(lambda: locked[0] in drains.robots("a"), timeout=5, what="the unlocked robot")


class Killable:
    """An executor whose loop can be frozen mid-run, as a killed process is: no clean-up, its membership (and its
    robots' locks) left to lapse. bury() lets the frozen loop end its tasks once the test is over."""

    def __init__(self, name: str, drain) -> None:
        self.executor = Executor(name, drain)
        self.loop = asyncio.new_event_loop()
        self.running = self.loop.create_task(self.executor.run())
        self.thread = self._host()
        wait_for(self.executor.ready.is_set, timeout=10, what=f"executor {name} ready")

    def _host(self) -> threading.Thread:
        def run() -> None:
            with contextlib.suppress(RuntimeError):  # "Event loop stopped before Future completed."
                self.loop.run_until_complete(self.running)

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        return thread

    def kill(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        assert not self.thread.is_alive()

    def bury(self) -> None:
        self.executor.stop()
        if not self.thread.is_alive():
            self.thread = self._host()
        self.thread.join(executor.JOIN_S)
        self.loop.close()


def test_a_killed_members_robots_are_taken_over_by_the_other_within_its_lapse():
    robots = waiting_robots(12)
    drains = Drains()
    a = Killable("a", drains.of("a"))
    try:
        with in_thread(name="b", drain=drains.of("b")) as b:
            owners = wait_for(
                lambda: split([a.executor, b], robots), timeout=5, what="a and b to see each other"
            )
            theirs = {robot_id for robot_id in robots if owners[robot_id] == "a"}
            assert theirs and theirs != set(robots)
            wait_for(lambda: drains.robots("a") >= theirs, timeout=5, what="a to run its robots")
            assert not drains.robots("b") & theirs  # b keeps off a's robots while a lives
            a.kill()
            killed_at, since = time.monotonic(), len(drains.started)
            wait_for(
                lambda: drains.robots("b", since) >= theirs, timeout=TAKE_OVER_S, what="b to take a's robots"
            )
            assert time.monotonic() - killed_at >= executor.MEMBER_TTL_MS / 1000 - 2 * executor.RENEW_S
            assert b.members == ("b",)
            assert drains.robots("a", since) == set()  # frozen: it runs nothing more
    finally:
        a.bury()


def test_stop_cancels_the_running_drains_and_leaves_the_members():
    drains = Drains(hold=60.0)
    with in_thread(name="a", drain=drains.of("a")) as a:
        assert a.members == ("a",)
        wake([1, 2, 3])
        wait_for(lambda: len(drains.started) == 3, timeout=5, what="three drains")
        stopping = time.monotonic()
    assert time.monotonic() - stopping < executor.HALT_WAIT_S
    assert sorted(drains.cancelled) == [("a", 1), ("a", 2), ("a", 3)]
    assert not any(thread.name == "executor a" for thread in threading.enumerate())
    client = coordination.connection()
    assert not client.exists(coordination.key("executor", "a"))
    assert not client.sismember(coordination.key("executors"), "a")


class Cuttable:
    """A TCP proxy to Redis whose connections can be cut (all closed, new ones refused) and then restored."""

    def __init__(self, host: str, port: int) -> None:
        self.target = (host, port)
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            self.port = probe.getsockname()[1]
        self.loop = asyncio.new_event_loop()
        threading.Thread(target=self.loop.run_forever, daemon=True).start()
        self.server: asyncio.Server | None = None
        self.streams: set[asyncio.StreamWriter] = set()
        self.restore()

    def _call(self, coroutine) -> None:
        asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(5)

    def restore(self) -> None:
        async def serve() -> None:
            self.server = await asyncio.start_server(self._pipe, "127.0.0.1", self.port)

        self._call(serve())

    def cut(self) -> None:
        async def close() -> None:
            self.server.close()
            for stream in self.streams:
                stream.close()

        self._call(close())

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        upstream_reader, upstream_writer = await asyncio.open_connection(*self.target)
        self.streams |= {writer, upstream_writer}
        await asyncio.gather(
            self._copy(reader, upstream_writer), self._copy(upstream_reader, writer), return_exceptions=True
        )

    async def _copy(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while data := await reader.read(65536):
                writer.write(data)
                await writer.drain()
        finally:
            writer.close()
            self.streams.discard(writer)


def test_a_redis_connection_cut_and_restored_leaves_the_executor_running_and_woken(settings):
    real = urlparse(settings.REDIS_URL)
    if real.scheme != "redis":
        pytest.skip("the proxy speaks TCP; this Redis is on a socket")
    proxy = Cuttable(real.hostname, real.port or 6379)
    direct = redis.Redis.from_url(settings.REDIS_URL)
    channel = coordination.key("wake")
    settings.REDIS_URL = (
        f"redis://127.0.0.1:{proxy.port}{real.path}"  # the executor's (and its sweep's) Redis
    )
    drains = Drains()
    with in_thread(name="a", drain=drains.of("a")) as a:
        proxy.cut()
        wait_for(lambda: a.members == (), timeout=5, what="the membership to fail")
        assert direct.pubsub_numsub(channel) == [(channel.encode(), 0)]  # its subscription went with it
        time.sleep(2 * executor.BACKOFF_MAX_S)  # retried, backing off, for a while
        proxy.restore()
        wait_for(lambda: a.members == ("a",), timeout=10, what="the membership back")
        wait_for(lambda: direct.pubsub_numsub(channel)[0][1] == 1, timeout=10, what="subscribed again")
        direct.publish(channel, json.dumps([7]))
        wait_for(lambda: drains.robots("a") == {7}, timeout=5, what="the wake-up after the outage")
    proxy.cut()
