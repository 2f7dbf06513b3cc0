"""execution.blocking: the executor's pool of threads for synchronous calls, and its pushes to browsers handed
back to the loop (live.deliver_on) instead of a new event loop, thread and Redis connection per push."""

import asyncio
import threading
import uuid

import pytest
from channels.layers import get_channel_layer

import live
from execution import blocking

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(30)]


async def _listening():
    layer = get_channel_layer()
    group, channel = f"test.blocking.{uuid.uuid4().hex[:8]}", await layer.new_channel()
    await layer.group_add(group, channel)
    return layer, group, channel


async def test_a_push_from_the_pool_goes_out_on_the_loop_not_through_a_new_event_loop(monkeypatch):
    layer, group, channel = await _listening()
    fresh_loops = []
    monkeypatch.setattr(live, "async_to_sync", lambda fn: fresh_loops.append(fn) or fn)
    sent_from = []

    def push(n: int) -> None:
        sent_from.append(threading.current_thread().name)
        live.send(group, {"type": "test.push", "n": n})

    try:
        for n in range(3):
            await blocking.call(push, n)
        got = [(await asyncio.wait_for(layer.receive(channel), 5))["n"] for _ in range(3)]
    finally:
        await blocking.close()
    assert sorted(got) == [0, 1, 2]
    assert all(name.startswith("executor-blocking") for name in sent_from)  # pushed from the pool's threads
    assert fresh_loops == []  # none of them went through async_to_sync


async def test_a_push_from_any_other_thread_still_goes_out(monkeypatch):
    layer, group, channel = await _listening()
    through = []
    real = live.async_to_sync
    monkeypatch.setattr(live, "async_to_sync", lambda fn: through.append(fn) or real(fn))
    thread = threading.Thread(target=live.send, args=(group, {"type": "test.push", "n": 7}))
    thread.start()
    await asyncio.to_thread(thread.join, 5)
    assert (await asyncio.wait_for(layer.receive(channel), 5))["n"] == 7
    assert len(through) == 1  # a plain thread has no loop to hand it to: async_to_sync, as before
