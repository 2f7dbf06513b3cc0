"""What the processes of the fleet agree on through Redis: robot locks, stop and preempt flags, last poses.

- A robot lock (SET NX PX, renewed while running) means at most one active instruction per robot across all
  workers; its value is the holder's token, also stored on the Execution it runs, so a watchdog can tell a
  running Execution whose worker died (no lock, or someone else's) from a live one.
- A stop flag holds the time of the last stop of a robot; a runner stops when it is newer than its start.
- A preempt flag names the Execution that interrupts the robot's current one.

Keys live under FLEET_EXEC_KEY_PREFIX, so test runs sharing one Redis do not meet.
"""

from __future__ import annotations

import functools
import os
import socket
import threading
import time
import uuid
import weakref

import redis
from django.conf import settings

LOCK_TTL_MS = 2500  # a dead worker's robot is found within this (plus one watchdog period)
STOP_FLAG_TTL_S = 600

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


def lock_holder(robot_id: int) -> str | None:
    """The token holding a robot's lock now, or None."""
    value = connection().get(key("lock", robot_id))
    return value.decode() if value else None


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
