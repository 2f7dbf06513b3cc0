"""channels_redis's RedisChannelLayer, with its per-channel cleanup lock's count kept right when a receive is
cancelled while it waits for that lock, and a cancelled receive that ends.

channels_redis (4.3) counts the waiters of each per-channel lock (ChannelLock) to drop the lock when nobody
waits, so that a lock is never reused on another event loop. A receive cancelled while waiting there (a consumer
disconnecting, the pose fanout's reader stopping, a recorder's receive timing out) counts in but never out: the
lock is kept for good, bound to the loop it waited on, and the first receive that must wait for it on a later loop
(a worker's next async_to_sync, a test's next asyncio.run) fails with "... is bound to a different event loop".

A receive cancelled just after it took over the layer's receive lock (the one blocking BZPOPMIN of the process)
may lose the cancel (channels_redis 4.3, redis-py 8.1, Python 3.11: about one time in ten when two sockets close
a millisecond apart): it goes on waiting in BZPOPMIN for a message that never comes, and its consumer with it.
A page's socket closed by the web server's graceful shutdown then held it until uvicorn gave up ("Cancel 1
running task(s), timeout graceful shutdown exceeded" on every Ctrl-C of `make run` with a page open). So a
receive here runs as a task of its own: cancelled, it is cancelled again until it has ended (a second cancel
always lands).
"""

from __future__ import annotations

import asyncio
import logging

from channels_redis import core

log = logging.getLogger(__name__)

RECANCEL_S = 0.05  # how long a cancelled receive is given to end before it is cancelled again
RECANCEL_TRIES = 40  # then it is left to end on its own (logged): the caller's cancel is not held up longer


class ChannelLock(core.ChannelLock):
    """The library's per-channel lock, counting out a waiter whose acquire failed (cancelled)."""

    async def acquire(self, channel):
        try:
            return await super().acquire(channel)
        except BaseException:
            self.wait_counts[channel] -= 1  # asyncio.Lock: a failed acquire does not hold the lock
            if self.wait_counts[channel] < 1:
                self.locks.pop(channel, None)
                self.wait_counts.pop(channel, None)
            raise


class RedisChannelLayer(core.RedisChannelLayer):
    """The Redis channel layer of every process (settings.CHANNEL_LAYERS)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.receive_clean_locks = ChannelLock()

    async def receive(self, channel):
        """The library's receive, which ends when it is cancelled (see the module's docstring)."""
        inner = asyncio.ensure_future(super().receive(channel))
        try:
            return await asyncio.shield(inner)
        except asyncio.CancelledError:
            await _cancelled(inner)
            raise


async def _cancelled(task: asyncio.Task) -> None:
    """Cancel the task until it has ended (bounded: RECANCEL_TRIES times, RECANCEL_S apart)."""
    for _ in range(RECANCEL_TRIES):
        task.cancel()
        done, _pending = await asyncio.wait({task}, timeout=RECANCEL_S)
        if done:
            if not task.cancelled() and task.exception() is not None:
                log.debug("a cancelled receive ended with %r", task.exception())
            return
    log.warning("a cancelled channel-layer receive did not end within %.1f s", RECANCEL_S * RECANCEL_TRIES)
