"""The executor process: one asyncio event loop that runs each of its robots' waiting work as one task.

`manage.py executor` runs one Executor per process; several processes (on one host or several) share the fleet:

- Membership. Each executor keeps a key of its own, coordination.key("executor", name), alive with a short time
  to live (MEMBER_TTL_MS, renewed every RENEW_S), and lists its name in one Redis set; the live members are the
  listed names whose key exists. A killed, frozen or cut-off process stops renewing and drops out by itself.
- Ownership by rendezvous (highest-random-weight) hashing: a robot belongs to the live member whose stable hash
  of "member:robot" is the highest. Every process computes the same owner from the same members without talking
  to the others, and when one member leaves (or joins) only its own robots move: every other robot's highest
  weight is unchanged. A modulo over the members would reshuffle nearly every robot at each change.
- Wake-up. Dispatch (after its commit) and the watchdog publish the robots' ids on one channel (wake()); every
  executor hears it and starts a task for each robot it owns and does not run yet. The task awaits the drain
  (execution.runner.drain_robot: the robot's queue, run under its Redis lock) and is forgotten when it returns.
- The sweep, every SWEEP_S, starts the owned robots that have waiting executions and whose lock nobody holds:
  a wake-up lost (Redis away, no executor listening yet) costs at most a sweep. It is also the fail-over: when a
  member dies its robots' owner changes, and the new owner's drain takes the robot's lock once the dead one's
  has lapsed (coordination.LOCK_TTL_MS). A member that loses a robot to a newcomer lets its running drain end;
  the lock keeps one runner per robot meanwhile.

Redis or the database away: each loop logs, retries with a bounded backoff, and never ends the process. No
thread per robot: the threads are the sweep's own for its query (so fail-over never queues behind the robots'
calls), the robots' shared pool for theirs (execution/blocking.py), and in_thread's host of the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

import redis
import redis.asyncio
from django.conf import settings
from django.db import close_old_connections, connections
from redis.asyncio.retry import Retry
from redis.backoff import NoBackoff

from execution import blocking, coordination, runner
from execution.models import Execution

log = logging.getLogger(__name__)

MEMBER_TTL_MS = 2000  # a member that has not renewed for this long is dead: its robots go to the others
RENEW_S = 0.5  # between renewals of the membership (and refreshes of the live members): three may be late
SWEEP_S = 1.0  # between looks for robots with waiting work (a lost wake-up costs this at most)
BACKOFF_S, BACKOFF_MAX_S = 0.1, 2.0  # a failing loop's first wait before a retry, doubling up to the max
REDIS_TIMEOUT_S = 2.0  # a Redis command (and a connect) of the loop fails after this long, once (no retries)
LOOPS_WAIT_S = 2.0  # on stop, the membership, listener and sweep loops get this long to end
HALT_WAIT_S = 5.0  # on stop, the robots' drains get this long to halt their robots after the cancel
DATABASE_CLOSE_S = 5.0  # on stop, the database thread gets this long to close its connection
READY_S = 10.0  # in_thread: the executor registers and subscribes within this, or the block is not entered
JOIN_S = 15.0  # in_thread: the hosting thread ends within this after stop()

Drain = Callable[[int], Awaitable[bool]]


def weight(member: str, robot_id: int) -> int:
    """The member's stable weight for a robot (the same in every process and every run)."""
    digest = hashlib.blake2b(f"{member}:{robot_id}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


def owner(robot_id: int, members: Iterable[str]) -> str | None:
    """The member a robot belongs to: the highest weight (ties, never seen, to the greater name); None: nobody."""
    return max(members, key=lambda member: (weight(member, robot_id), member), default=None)


def wake(robot_ids: Iterable[int]) -> None:
    """Ask the executors to start these robots (one message; each owner starts its own). Redis away: logged,
    not raised (the caller's commit stands; the owners' sweep finds the robots within SWEEP_S of Redis's return)."""
    ids = sorted({int(robot_id) for robot_id in robot_ids})
    if not ids:
        return
    try:
        coordination.connection().publish(coordination.key("wake"), json.dumps(ids))
    except redis.RedisError as exc:
        log.warning("robots %s not woken (the executors' sweep will find them): %s", ids, exc)


def live_members() -> list[str]:
    """The executors alive now (listed, and their membership not lapsed), from any process: for benches and
    tools that wait for them."""
    redis_ = coordination.connection()
    names = sorted(name.decode() for name in redis_.smembers(coordination.key("executors")))
    alive = redis_.mget([coordination.key("executor", name) for name in names]) if names else []
    return [name for name, value in zip(names, alive, strict=True) if value is not None]


def waiting_robots() -> list[int]:
    """Robots with waiting executions whose lock nobody holds (blocking: run in the database thread)."""
    close_old_connections()  # a connection the database dropped, or past its age, is made again
    waiting = Execution.objects.filter(status__in=runner.WAITING).order_by()
    robot_ids = sorted(set(waiting.values_list("robot_id", flat=True)))
    holders = coordination.lock_holders(robot_ids)
    return [robot_id for robot_id in robot_ids if holders[robot_id] is None]


class Backoff:
    """The waits of a loop whose step fails: BACKOFF_S, doubling up to BACKOFF_MAX_S; the first failure of an
    outage is logged, and the recovery."""

    def __init__(self, what: str) -> None:
        self.what = what
        self.failures = 0

    async def failed(self, exc: Exception) -> None:
        """Wait before the next try (said once per outage)."""
        if not self.failures:
            log.warning("%s failed, retrying: %s: %s", self.what, type(exc).__name__, exc)
        self.failures += 1
        await asyncio.sleep(min(BACKOFF_MAX_S, BACKOFF_S * 2 ** (self.failures - 1)))

    def succeeded(self) -> None:
        """The step worked: the next failure waits BACKOFF_S again."""
        if self.failures:
            log.info("%s back after %d failures", self.what, self.failures)
        self.failures = 0


class Executor:
    """One process's executor: its membership, the wake listener, the sweep and one task per running robot."""

    def __init__(self, name: str | None = None, drain: Drain | None = None) -> None:
        self.name = name or coordination.new_token()
        self.drain: Drain = drain if drain is not None else runner.drain_robot
        self.ready = threading.Event()  # set once registered as a member and subscribed to wake-ups
        self._unready = {"member", "listener"}
        self._members: tuple[str, ...] = ()  # the live members at the last renewal; () while Redis is away
        self._running: dict[int, asyncio.Task] = {}
        self._stop_asked = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None

    @property
    def members(self) -> tuple[str, ...]:
        """The live members as last seen (this one among them while its membership is renewed)."""
        return self._members

    def owns(self, robot_id: int) -> bool:
        """Whether the robot is this executor's, by rendezvous over the live members."""
        return owner(robot_id, self._members) == self.name

    def stop(self) -> None:
        """Ask run() to end, from any thread (or before it started): robot tasks cancelled, membership removed."""
        self._stop_asked.set()
        if self._loop is not None and self._stopping is not None:
            with contextlib.suppress(RuntimeError):  # the loop has ended already
                self._loop.call_soon_threadsafe(self._stopping.set)

    async def run(self) -> None:
        """Be a member, listen for wake-ups and sweep, running owned robots, until stop()."""
        self._stopping = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        if self._stop_asked.is_set():
            return
        client = redis.asyncio.Redis.from_url(
            settings.REDIS_URL,
            socket_timeout=REDIS_TIMEOUT_S,
            socket_connect_timeout=REDIS_TIMEOUT_S,
            retry=Retry(NoBackoff(), 0),  # the loops retry, with their backoff
        )
        database = ThreadPoolExecutor(max_workers=1, thread_name_prefix="executor database")
        loops = [
            asyncio.create_task(self._forever("membership", lambda: self._renew(client), RENEW_S)),
            asyncio.create_task(self._listen(client)),
            asyncio.create_task(self._forever("sweep", lambda: self._sweep(database), SWEEP_S)),
        ]
        log.info("executor %s running", self.name)
        try:
            await self._stopping.wait()
        finally:
            await self._end(loops, client, database)

    async def _end(
        self, loops: list[asyncio.Task], client: redis.asyncio.Redis, database: ThreadPoolExecutor
    ) -> None:
        """Stop the loops, halt the robots, leave the members, close the connections."""
        self._stopping.set()  # also when run() itself was cancelled: no loop goes round again
        for task in loops:
            task.cancel()
        _, late = await asyncio.wait(loops, timeout=LOOPS_WAIT_S)
        if late:
            log.warning("executor %s: %d loops still ending after the stop", self.name, len(late))
        await self._halt_robots()
        await self._leave(client)
        await client.aclose()
        with contextlib.suppress(TimeoutError):
            closing = asyncio.get_running_loop().run_in_executor(database, connections.close_all)
            await asyncio.wait_for(closing, DATABASE_CLOSE_S)
        database.shutdown(wait=False)
        await blocking.close()  # the robots' blocking pool, with its connections
        log.info("executor %s stopped", self.name)

    async def _forever(self, what: str, step: Callable[[], Awaitable[None]], period: float) -> None:
        """Run step every period until stopped; a failure is retried after a backoff."""
        backoff = Backoff(f"executor {self.name}: {what}")
        while not self._stopping.is_set():
            try:
                await step()
            except Exception as exc:
                await backoff.failed(exc)
                continue
            backoff.succeeded()
            await asyncio.sleep(period)

    async def _renew(self, client: redis.asyncio.Redis) -> None:
        """Renew this membership and read the live members (the lapsed ones are struck from the list)."""
        listed = coordination.key("executors")
        try:
            async with client.pipeline(transaction=False) as pipe:
                pipe.set(coordination.key("executor", self.name), 1, px=MEMBER_TTL_MS)
                pipe.sadd(listed, self.name)
                pipe.smembers(listed)
                *_, names = await pipe.execute()
            names = sorted(name.decode() for name in names)
            alive = await client.mget([coordination.key("executor", name) for name in names])
        except Exception:
            self._members = ()  # not renewed: another member may have our robots by now
            raise
        self._members = tuple(name for name, value in zip(names, alive, strict=True) if value is not None)
        self._ready("member")
        lapsed = set(names) - set(self._members)
        if lapsed:
            await client.srem(listed, *lapsed)

    async def _listen(self, client: redis.asyncio.Redis) -> None:
        """Listen for wake-ups until stopped, starting the owned robots each names; a lost connection is
        subscribed again after a backoff (a wake-up meanwhile is the sweep's)."""
        backoff = Backoff(f"executor {self.name}: wake listener")
        while not self._stopping.is_set():
            try:
                async with client.pubsub() as pubsub:
                    await self._subscribe(pubsub)
                    backoff.succeeded()
                    self._ready("listener")
                    while not self._stopping.is_set():
                        message = await pubsub.get_message(ignore_subscribe_messages=True, timeout=None)
                        if message is not None:
                            self._start_owned(json.loads(message["data"]))
            except Exception as exc:
                await backoff.failed(exc)

    @staticmethod
    async def _subscribe(pubsub: redis.asyncio.client.PubSub) -> None:
        """Subscribe to wake-ups and wait for Redis to confirm it (a wake-up published after that is heard)."""
        await pubsub.subscribe(coordination.key("wake"))
        confirmed = await pubsub.get_message(timeout=REDIS_TIMEOUT_S)
        if not confirmed or confirmed["type"] != "subscribe":
            raise redis.ConnectionError(f"the subscription to wake-ups was not confirmed: {confirmed}")

    async def _sweep(self, database: ThreadPoolExecutor) -> None:
        """Start the owned robots with waiting work that nobody runs."""
        loop = asyncio.get_running_loop()
        self._start_owned(await loop.run_in_executor(database, waiting_robots))

    def _ready(self, part: str) -> None:
        """One part is up ("member", "listener"); ready once both are."""
        self._unready.discard(part)
        if not self._unready:
            self.ready.set()

    def _start_owned(self, robot_ids: Iterable[int]) -> None:
        """A task for each robot of this executor's that has none running."""
        for robot_id in robot_ids:
            if robot_id not in self._running and self.owns(robot_id):
                self._running[robot_id] = asyncio.create_task(self._drain(robot_id), name=f"robot {robot_id}")

    async def _drain(self, robot_id: int) -> None:
        """One robot's task: its drain, then forgotten (a failure is logged; the sweep starts it again)."""
        try:
            await self.drain(robot_id)
        except Exception:
            log.exception("executor %s: robot %s's drain failed", self.name, robot_id)
        finally:
            self._running.pop(robot_id, None)

    async def _halt_robots(self) -> None:
        """Cancel every robot's task (its drain halts the robot) and wait for them, HALT_WAIT_S at most."""
        tasks = list(self._running.values())
        for task in tasks:
            task.cancel()
        if tasks:
            _, late = await asyncio.wait(tasks, timeout=HALT_WAIT_S)
            if late:
                log.warning("executor %s: %d robot tasks still ending after the stop", self.name, len(late))

    async def _leave(self, client: redis.asyncio.Redis) -> None:
        """Drop this membership at once (Redis away: it lapses within MEMBER_TTL_MS by itself)."""
        try:
            async with client.pipeline(transaction=False) as pipe:
                pipe.delete(coordination.key("executor", self.name))
                pipe.srem(coordination.key("executors"), self.name)
                await pipe.execute()
        except (redis.RedisError, OSError) as exc:
            log.warning("executor %s: membership not removed (it lapses by itself): %r", self.name, exc)
        self._members = ()


@contextlib.contextmanager
def in_thread(**kwargs) -> Iterator[Executor]:
    """An Executor whose loop runs in a daemon thread of this process (tests, a development server), ready
    (registered, subscribed) when the block starts; stopped and joined when it ends."""
    executor = Executor(**kwargs)
    thread = threading.Thread(
        target=asyncio.run, args=(executor.run(),), name=f"executor {executor.name}", daemon=True
    )
    thread.start()
    try:
        deadline = time.monotonic() + READY_S
        while not executor.ready.wait(0.05):
            if not thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"executor {executor.name} not ready within {READY_S:g} s (is Redis up?)")
        yield executor
    finally:
        executor.stop()
        thread.join(JOIN_S)
        if thread.is_alive():
            log.error("executor %s: its thread did not end within %g s of the stop", executor.name, JOIN_S)
