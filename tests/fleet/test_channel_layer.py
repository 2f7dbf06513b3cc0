"""The channel layer's per-channel lock after a receive cancelled while waiting on it: dropped, so the next event
loop of the process (a test's next asyncio.run, a worker's next async_to_sync) gets a lock of its own."""

from __future__ import annotations

import asyncio

from fleet.channel_layer import ChannelLock


def test_a_waiter_cancelled_on_one_loop_leaves_no_lock_bound_to_it():
    lock = ChannelLock()

    async def cancelled_waiter():
        await lock.acquire("c")  # held
        waiter = asyncio.ensure_future(lock.acquire("c"))  # waits: the lock binds to this loop
        await asyncio.sleep(0)
        waiter.cancel()
        await asyncio.gather(waiter, return_exceptions=True)
        lock.release("c")

    async def contended():
        await lock.acquire("c")
        waiter = asyncio.ensure_future(lock.acquire("c"))
        await asyncio.sleep(0)
        lock.release("c")
        assert await asyncio.wait_for(waiter, 5) is True  # a lock bound to the first loop would raise here
        lock.release("c")

    asyncio.run(cancelled_waiter())
    assert lock.locks == {} and lock.wait_counts == {}
    asyncio.run(contended())
    assert lock.locks == {} and lock.wait_counts == {}


def test_a_receive_cancelled_as_it_takes_over_the_receive_lock_ends():
    """Two sockets closing a millisecond apart: the second receive, cancelled just after it took over the layer's
    receive lock, lost the cancel about one time in ten (channels_redis alone) and waited in BZPOPMIN for good,
    holding its consumer, so uvicorn's graceful shutdown ran out. Each cancelled receive now ends."""
    from channels.layers import get_channel_layer

    async def rounds(count: int) -> list[int]:
        layer = get_channel_layer()
        channels = [await layer.new_channel() for _ in range(3)]
        stuck = []
        for i in range(count):
            receives = [asyncio.ensure_future(layer.receive(channel)) for channel in channels]
            await asyncio.sleep(0.1)  # every receive waiting, one of them in BZPOPMIN
            for receive in receives:
                receive.cancel()
                done, _ = await asyncio.wait({receive}, timeout=1.0)  # a hang guard, not a speed claim
                if not done:
                    stuck.append(i)
                await asyncio.sleep(0.001 * (i % 3))
        return stuck

    assert asyncio.run(rounds(30)) == []
