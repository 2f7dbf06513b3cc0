"""What the processes of the fleet agree on through Redis: robot locks, stop and preempt flags, last poses.

- A robot lock (SET NX PX) means at most one active instruction per robot across all executors; its value is
  the holder's token, also stored on the Execution it runs, so a watchdog can tell a running Execution whose
  executor died (no lock, or someone else's) from a live one. The holder's board (execution/board.py) renews
  it every HEARTBEAT_S while the command loop beats: a killed or frozen executor lets it lapse within
  LOCK_TTL_MS, and the scheduler's watchdog (execution/watchdog.py, every WATCHDOG_S) then stops the robot. A
  holder's process also stays subscribed to a presence channel of its own while it lives: a killed or crashed
  process's subscription ends with its socket, and the watchdog stops its robots without waiting for the lapse.
- A stop flag holds the time of the last stop of a robot; a runner stops when it is newer than its start.
- A preempt flag names the Execution that interrupts the robot's current one.
- A cancel flag holds who cancelled one Execution (one instruction cancelled); its runner stops it.
- Raising any of these flags also publishes on the `flags` channel: each executor's board reads its robots'
  flags at once (execution/board.py), not at its next tick.

Keys live under FLEET_EXEC_KEY_PREFIX, so test runs sharing one Redis do not meet.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import os
import socket
import threading
import time
import uuid
import weakref

import redis
import redis.asyncio
from django.conf import settings
from redis.asyncio.retry import Retry as AsyncRetry
from redis.backoff import NoBackoff
from redis.retry import Retry

# a frozen executor's robot is found within this plus one watchdog period (a killed one's sooner: its presence)
LOCK_TTL_MS = 1000
HEARTBEAT_S = 0.25  # between renewals: three may be late before the lock lapses
LIVELY_S = 5.0  # a command loop that has not beaten for this long is hung: the heartbeat stops renewing
WATCHDOG_S = 0.25  # the scheduler process looks for lapsed locks this often
STOP_FLAG_TTL_S = 600
STOP_REDIS_TIMEOUT_S = 0.25  # a stop's flags wait this long at most: a frozen Redis delays no answer by more

log = logging.getLogger(__name__)

RELEASE = "if redis.call('get', KEYS[1]) == ARGV[1] then return redis.call('del', KEYS[1]) else return 0 end"
# Renew locks (an executor's board, all of its own at once): KEYS the locks, ARGV each one's token and time to live
# in turn; for each, 1 renewed or 0 not ours any more. One script run for all of them.
RENEW_MANY = """
local out = {}
for i, k in ipairs(KEYS) do
  if redis.call('get', k) == ARGV[2 * i - 1] then out[i] = redis.call('pexpire', k, ARGV[2 * i]) else out[i] = 0 end
end
return out
"""


@functools.cache
def _connection(pid: int, url: str) -> redis.Redis:
    return redis.Redis.from_url(url, socket_timeout=5, health_check_interval=30)


def connection() -> redis.Redis:
    """This process's Redis client (a new one after a fork)."""
    return _connection(os.getpid(), settings.REDIS_URL)


@functools.cache
def _stop_connection(pid: int, url: str) -> redis.Redis:
    limit = STOP_REDIS_TIMEOUT_S
    return redis.Redis.from_url(url, socket_timeout=limit, socket_connect_timeout=limit, retry=_no_retry())


def _no_retry(on_loop: bool = False):
    """One attempt: a stop does not wait for a Redis that does not answer at once."""
    return (AsyncRetry if on_loop else Retry)(NoBackoff(), 0)


def stop_connection() -> redis.Redis:
    """The client a stop's flags go through: short timeouts and no retries, so a frozen Redis costs a stop
    STOP_REDIS_TIMEOUT_S at most (the zeros are already out; the stop's answer says the flags were not raised)."""
    return _stop_connection(os.getpid(), settings.REDIS_URL)


def key(*parts) -> str:
    prefix = getattr(settings, "FLEET_EXEC_KEY_PREFIX", "") or "fleet:exec"
    return ":".join([prefix, *map(str, parts)])


def process_name() -> str:
    """This process as the tokens it makes name it: host:pid."""
    return f"{socket.gethostname()}:{os.getpid()}"


def new_token() -> str:
    """A token naming this worker, process and thread uniquely (its process first: holder_process)."""
    return f"{process_name()}:{threading.get_ident()}:{uuid.uuid4().hex[:8]}"


def holder_process(token: str) -> str | None:
    """The process (host:pid) that made a token, or None for a token not made by new_token."""
    host, _, rest = token.partition(":")
    pid = rest.partition(":")[0]
    return f"{host}:{pid}" if host and pid.isdigit() else None


def presence_channel(process: str) -> str:
    """The channel a process holding robot locks stays subscribed to while it lives (execution.board): Redis
    drops the subscription the moment the process's socket closes, which a kill -9 or a crash does at once."""
    return key("alive", process)


def present(processes) -> dict[str, bool]:
    """{process: whether it is subscribed to its presence channel now}, in one round trip (PUBSUB NUMSUB)."""
    processes = list(processes)
    if not processes:
        return {}
    counts = connection().pubsub_numsub(*(presence_channel(process) for process in processes))
    return {process: count > 0 for process, (_, count) in zip(processes, counts, strict=True)}


class RobotLock:
    """The one-runner-per-robot lock with expiry; renew() while running, release() at the end."""

    def __init__(self, robot_id: int, token: str | None = None, ttl_ms: int = LOCK_TTL_MS) -> None:
        self.robot_id = robot_id
        self.key = key("lock", robot_id)
        self.token = token or new_token()
        self.ttl_ms = ttl_ms

    def acquire(self) -> bool:
        return bool(connection().set(self.key, self.token, nx=True, px=self.ttl_ms))

    def release(self) -> None:
        connection().eval(RELEASE, 1, self.key, self.token)


def lock_holders(robot_ids) -> dict[int, str | None]:
    """{robot id: the token holding its lock, or None}, in one round trip."""
    robot_ids = list(robot_ids)
    if not robot_ids:
        return {}
    values = connection().mget([key("lock", robot_id) for robot_id in robot_ids])
    return {rid: value.decode() if value else None for rid, value in zip(robot_ids, values, strict=True)}


def request_stop(robot_ids) -> float:
    """Raise the stop flag of these robots (one round trip, bounded) and return its time; redis errors raise."""
    now = time.time()
    pipe = stop_connection().pipeline(transaction=False)
    for robot_id in robot_ids:
        pipe.set(key("stop", robot_id), repr(now), ex=STOP_FLAG_TTL_S)
    pipe.publish(key("flags"), "stop")
    pipe.execute()
    return now


_ASYNC: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # loop -> {(use, url): redis.asyncio client}


def aconnection(stop: bool = False) -> redis.asyncio.Redis:
    """This event loop's own Redis client (connection(), or with stop=True stop_connection(), for code on a
    loop): one per loop, as a redis.asyncio client cannot move between loops."""
    clients = _ASYNC.setdefault(asyncio.get_running_loop(), {})  # by URL: a loop outlives a test's settings
    client = clients.get((stop, settings.REDIS_URL))
    if client is None:
        if stop:
            limit = STOP_REDIS_TIMEOUT_S
            options = {
                "socket_timeout": limit,
                "socket_connect_timeout": limit,
                "retry": _no_retry(on_loop=True),
            }
        else:
            options = {"socket_timeout": 5}
        client = clients[(stop, settings.REDIS_URL)] = redis.asyncio.Redis.from_url(
            settings.REDIS_URL, **options
        )
    return client


async def arequest_stop(robot_ids) -> float:
    """request_stop for code on an event loop: the same flags, over this loop's own Redis connection (bounded by
    STOP_REDIS_TIMEOUT_S as a whole; TimeoutError or a redis error raise)."""
    client = aconnection(stop=True)
    now = time.time()

    async def flags() -> None:
        async with client.pipeline(transaction=False) as pipe:
            for robot_id in robot_ids:
                pipe.set(key("stop", robot_id), repr(now), ex=STOP_FLAG_TTL_S)
            pipe.publish(key("flags"), "stop")
            await pipe.execute()

    await asyncio.wait_for(flags(), STOP_REDIS_TIMEOUT_S * 2)
    return now


def request_preempt(robot_id: int, execution_id: int) -> None:
    pipe = connection().pipeline(transaction=False)
    pipe.set(key("preempt", robot_id), execution_id, ex=STOP_FLAG_TTL_S)
    pipe.publish(key("flags"), "preempt")
    pipe.execute()


def clear_preempt(robot_id: int, execution_id: int | None = None) -> None:
    """Drop the preempt flag (only if it still names execution_id, when given)."""
    if execution_id is None:
        connection().delete(key("preempt", robot_id))
    else:
        connection().eval(RELEASE, 1, key("preempt", robot_id), str(execution_id))


UNRECORDED_TTL_S = 7 * 24 * 3600  # an end the database could not take waits this long for the sweep


def note_unrecorded_end(execution_id: int, words: str) -> None:
    """Keep how an execution ended when the database refused to record it (the watchdog's sweep records these
    words once the database takes writes again, instead of "executor lost"); Redis errors raise."""
    connection().set(key("unrecorded", execution_id), words.encode(), ex=UNRECORDED_TTL_S)


def unrecorded_ends(execution_ids) -> dict[int, str]:
    """{execution id: the words kept by note_unrecorded_end} for those that have some (one round trip)."""
    ids = list(execution_ids)
    values = connection().mget([key("unrecorded", pk) for pk in ids]) if ids else []
    return {pk: value.decode() for pk, value in zip(ids, values, strict=True) if value}


def forget_unrecorded_end(execution_id: int) -> None:
    connection().delete(key("unrecorded", execution_id))


def flags(robot_id: int) -> tuple[float, int | None]:
    """(time of the last stop or 0, the execution id that preempts this robot or None), in one round trip."""
    stop, preempt = connection().mget(key("stop", robot_id), key("preempt", robot_id))
    return (float(stop) if stop else 0.0), (int(preempt) if preempt else None)


def request_cancel(execution_ids, words: str) -> None:
    """Flag these executions cancelled (one instruction cancelled: execution.tasklist), with who did it in words;
    the runner of each stops it on its next tick. Keyed by execution, so no other work of the robot is touched."""
    pipe = connection().pipeline(transaction=False)
    for execution_id in execution_ids:
        pipe.set(key("cancel", execution_id), words, ex=STOP_FLAG_TTL_S)
    pipe.publish(key("flags"), "cancel")
    pipe.execute()


def session_flags(robot_id: int, execution_id: int) -> tuple[float, int | None, str | None]:
    """flags() and the execution's cancel words (None: not cancelled), in one round trip: a runner's tick."""
    stop, preempt, cancel = connection().mget(
        key("stop", robot_id), key("preempt", robot_id), key("cancel", execution_id)
    )
    words = cancel.decode() if cancel else None
    return (float(stop) if stop else 0.0), (int(preempt) if preempt else None), words
