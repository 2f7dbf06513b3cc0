"""The executor's way out of its event loop: the database, the traffic tables and the pushes to browsers are
synchronous (the Django ORM, redis-py), so a robot's task hands each such call to one small pool of threads
shared by every robot of the loop, and the loop goes on ticking the others meanwhile. A push to browsers made in
one of these threads is handed back to the loop (live.deliver_on), which sends it on its own Redis connection.

One pool per event loop (an executor process has one), never a thread per robot: POOL_THREADS calls at a time, the
rest queue. (The executor's sweep and membership have a database thread of their own, so that finding waiting work
never queues behind the robots' planning: execution/executor.py.) A database that holds a call for seconds
(locked, restarting) holds that robot's step, not the others' control ticks. Each thread keeps its database
connection between calls (a connect per call would cost more than most queries); one the database dropped is made
again. close() ends the pool with its connections.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor

from django.db import connections

import live

POOL_THREADS = 8  # blocking calls of one executor at a time (32 robots planning at once queue here)
CLOSE_WAIT_S = 5.0  # close(): each thread gets this long to close its connections

_pools: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, ThreadPoolExecutor] = weakref.WeakKeyDictionary()


def _pool() -> ThreadPoolExecutor:
    loop = asyncio.get_running_loop()
    pool = _pools.get(loop)
    if pool is None:
        pool = _pools[loop] = ThreadPoolExecutor(
            POOL_THREADS,
            thread_name_prefix="executor-blocking",
            initializer=live.deliver_on,
            initargs=(loop,),
        )
    return pool


def _usable(fn, *args, **kwargs):
    for connection in connections.all(initialized_only=True):
        if connection.errors_occurred and not connection.is_usable():  # dropped (a restart): made again
            connection.close()
    return fn(*args, **kwargs)


async def call(fn, /, *args, **kwargs):
    """Run fn(*args, **kwargs) on the loop's blocking pool; its result, or its exception, here."""
    return await asyncio.get_running_loop().run_in_executor(
        _pool(), functools.partial(_usable, fn, *args, **kwargs)
    )


async def close() -> None:
    """End the running loop's pool: every thread closes its database connections, then the threads end."""
    pool = _pools.pop(asyncio.get_running_loop(), None)
    if pool is None:
        return
    everyone = threading.Barrier(POOL_THREADS, timeout=CLOSE_WAIT_S)  # one task per thread: none takes two

    def close_own() -> None:
        connections.close_all()
        with contextlib.suppress(threading.BrokenBarrierError):  # a thread still busy: its connection lapses
            everyone.wait()

    loop = asyncio.get_running_loop()
    await asyncio.gather(*(loop.run_in_executor(pool, close_own) for _ in range(POOL_THREADS)))
    pool.shutdown(wait=False)
