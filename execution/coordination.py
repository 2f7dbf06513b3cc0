"""What the processes of the fleet agree on through Redis: robot locks, stop and preempt flags, last poses.

- A robot lock (SET NX PX) means at most one active instruction per robot across all workers; its value is the
  holder's token, also stored on the Execution it runs, so a watchdog can tell a running Execution whose worker
  died (no lock, or someone else's) from a live one. The holder's Heartbeat renews it every HEARTBEAT_S while
  the command loop beats: a killed or frozen executor lets it lapse within LOCK_TTL_MS, and the scheduler's
  watchdog (execution/watchdog.py, every WATCHDOG_S) then stops the robot.
- A stop flag holds the time of the last stop of a robot; a runner stops when it is newer than its start.
- A preempt flag names the Execution that interrupts the robot's current one.

Keys live under FLEET_EXEC_KEY_PREFIX, so test runs sharing one Redis do not meet.
"""

from __future__ import annotations

import functools
import logging
import os
import socket
import threading
import time
import uuid
import weakref

import redis
from django.conf import settings

LOCK_TTL_MS = 1000  # a dead executor's robot is found within this plus one watchdog period (under 2 s)
HEARTBEAT_S = 0.25  # between renewals: three may be late before the lock lapses
LIVELY_S = 5.0  # a command loop that has not beaten for this long is hung: the heartbeat stops renewing
WATCHDOG_S = 0.25  # the scheduler process looks for lapsed locks this often
STOP_FLAG_TTL_S = 600

log = logging.getLogger(__name__)

RELEASE = "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('del', KEYS[1]) else return 0 end"
RENEW = (
    "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('pexpire', KEYS[1], ARGV[2]) "
    "else return 0 end"
)


@functools.cache
def _connection(pid: int, url: str) -> redis.Redis:
    return redis.Redis.from_url(url, socket_timeout=5, health_check_interval=30)


def connection() -> redis.Redis:
    """This process's Redis client (a new one after a fork)."""
    return _connection(os.getpid(), settings.REDIS_URL)


def key(*parts) -> str:
    prefix = getattr(settings, "FLEET_EXEC_KEY_PREFIX", "") or "fleet:exec"
    return ":".join([prefix, *map(str, parts)])


def new_token() -> str:
    """A token naming this worker, process and thread uniquely."""
    return f"{socket.gethostname()}:{os.getpid()}:{threading.get_ident()}:{uuid.uuid4().hex[:8]}"


class RobotLock:
    """The one-runner-per-robot lock with expiry; renew() while running, release() at the end."""

    def __init__(self, robot_id: int, token: str | None = None, ttl_ms: int = LOCK_TTL_MS) -> None:
        self.key = key("lock", robot_id)
        self.token = token or new_token()
        self.ttl_ms = ttl_ms

    def acquire(self) -> bool:
        return bool(connection().set(self.key, self.token, nx=True, px=self.ttl_ms))

    def renew(self) -> bool:
        """Extend the lock; False if it was lost (expired and taken, or released)."""
        return bool(connection().eval(RENEW, 1, self.key, self.token, self.ttl_ms))

    def release(self) -> None:
        connection().eval(RELEASE, 1, self.key, self.token)


class Heartbeat:
    """Keep a held RobotLock alive from a thread of its own, as long as the command loop beats.

    The holder of a robot's command stream proves it is alive by renewing the lock every HEARTBEAT_S. A killed
    or frozen process renews nothing (its threads die or freeze with it), so the lock lapses within its time to
    live; a command loop that hangs inside a live process stops beating, and LIVELY_S later the heartbeat stops
    renewing, with the same result. Either way the watchdog then stops the robot. The command loop asks `held`
    before each command: a lock that could not be confirmed within its time to live is not ours any more.
    """

    def __init__(self, lock: RobotLock, every: float = HEARTBEAT_S, lively: float = LIVELY_S) -> None:
        self.lock, self.every, self.lively = lock, every, lively
        self.renewed = self.alive_until = 0.0
        self.lost = self.quiet = False
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"heartbeat {lock.key}", daemon=True)

    @property
    def token(self) -> str:
        return self.lock.token

    def start(self) -> Heartbeat:
        """Start renewing (call right after the lock was acquired)."""
        self.renewed = time.monotonic()
        self.beat()
        self._thread.start()
        return self

    def beat(self) -> None:
        """The command loop is alive: keep renewing for another LIVELY_S."""
        self.alive_until = time.monotonic() + self.lively

    @property
    def why_lost(self) -> str:
        """Why the lock is not ours, in a person's words (for the execution's outcome)."""
        if self.lost:
            return "its lock on the robot lapsed before it was renewed (it is not ours any more)"
        if self.quiet:
            return f"its command loop did not run for {self.lively:g} s, so its lock on the robot lapsed"
        return f"its lock on the robot was not renewed for {self.lock.ttl_ms / 1000:g} s (a starved process?)"

    @property
    def held(self) -> bool:
        """Whether the lock is still ours: never refused, and confirmed within its time to live."""
        return not self.lost and time.monotonic() - self.renewed < self.lock.ttl_ms / 1000

    def stop(self) -> None:
        self._stopping.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2 * self.every + 1)

    def _run(self) -> None:
        while not self._stopping.wait(self.every):
            self.quiet = time.monotonic() > self.alive_until
            if self.quiet:
                continue  # the command loop is hung: let the lock lapse so the watchdog takes over
            sent = time.monotonic()
            try:
                renewed = self.lock.renew()
            except Exception as exc:  # Redis away: try again; `held` turns false once the lock has lapsed
                log.warning("%s: heartbeat not renewed: %s", self.lock.key, exc)
                continue
            if not renewed:
                log.warning("%s: lost, %.1f s after its last renewal", self.lock.key, sent - self.renewed)
                self.lost = True  # expired and taken, or released: never ours again
                return
            self.renewed = sent


def lock_holder(robot_id: int) -> str | None:
    """The token holding a robot's lock now, or None."""
    value = connection().get(key("lock", robot_id))
    return value.decode() if value else None


def lock_holders(robot_ids) -> dict[int, str | None]:
    """{robot id: the token holding its lock, or None}, in one round trip."""
    robot_ids = list(robot_ids)
    if not robot_ids:
        return {}
    values = connection().mget([key("lock", robot_id) for robot_id in robot_ids])
    return {rid: value.decode() if value else None for rid, value in zip(robot_ids, values, strict=True)}


def request_stop(robot_ids) -> float:
    """Raise the stop flag of these robots (one round trip) and return its time."""
    now = time.time()
    pipe = connection().pipeline(transaction=False)
    for robot_id in robot_ids:
        pipe.set(key("stop", robot_id), repr(now), ex=STOP_FLAG_TTL_S)
    pipe.execute()
    return now


_ASYNC: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # event loop -> redis.asyncio client


async def arequest_stop(robot_ids) -> float:
    """request_stop for code on an event loop: the same flags, over this loop's own Redis connection."""
    import asyncio

    import redis.asyncio

    loop = asyncio.get_running_loop()
    client = _ASYNC.get(loop)
    if client is None:
        client = _ASYNC[loop] = redis.asyncio.Redis.from_url(settings.REDIS_URL, socket_timeout=5)
    now = time.time()
    async with client.pipeline(transaction=False) as pipe:
        for robot_id in robot_ids:
            pipe.set(key("stop", robot_id), repr(now), ex=STOP_FLAG_TTL_S)
        await pipe.execute()
    return now


def request_preempt(robot_id: int, execution_id: int) -> None:
    connection().set(key("preempt", robot_id), execution_id, ex=STOP_FLAG_TTL_S)


def clear_preempt(robot_id: int, execution_id: int | None = None) -> None:
    """Drop the preempt flag (only if it still names execution_id, when given)."""
    if execution_id is None:
        connection().delete(key("preempt", robot_id))
    else:
        connection().eval(RELEASE, 1, key("preempt", robot_id), str(execution_id))


def flags(robot_id: int) -> tuple[float, int | None]:
    """(time of the last stop or 0, the execution id that preempts this robot or None), in one round trip."""
    stop, preempt = connection().mget(key("stop", robot_id), key("preempt", robot_id))
    return (float(stop) if stop else 0.0), (int(preempt) if preempt else None)
