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
        got = await _received(layer, channel, 3)
    finally:
        await blocking.close()
    assert got == [0, 1, 2]
    assert all(name.startswith("executor-blocking") for name in sent_from)  # pushed from the pool's threads
    assert fresh_loops == []  # none of them went through async_to_sync


async def _received(layer, channel, count: int) -> list[int]:
    """The n of the first `count` pushes read from the channel (a handed-over burst comes batched)."""
    got = []
    while len(got) < count:
        got += [push["n"] for push in live.unbatched(await asyncio.wait_for(layer.receive(channel), 5))]
    return got


async def test_a_burst_of_pushes_from_the_pool_goes_in_order_one_send_at_a_time(monkeypatch):
    """An executor starting 50 robots pushes hundreds of task lists and statuses from its pool at once: they go
    one channel-layer send at a time, in their order, each group's waiting ones in one message (a task per push
    had hundreds of sends in flight: the layer's 100 connections ran out, bench.cluster)."""
    layer, group, channel = await _listening()
    real, in_flight, most = live._send_bounded, [0], [0]

    async def counted(layer_, group_, payload):
        in_flight[0] += 1
        most[0] = max(most[0], in_flight[0])
        try:
            await real(layer_, group_, payload)
        finally:
            in_flight[0] -= 1

    monkeypatch.setattr(live, "_send_bounded", counted)
    pushes = 300

    def burst(start: int) -> None:
        for n in range(start, start + pushes // 3):
            live.send(group, {"type": "test.push", "n": n})

    try:
        await asyncio.gather(*(blocking.call(burst, start) for start in (0, 100, 200)))
        got = await _received(layer, channel, pushes)
    finally:
        await blocking.close()
    assert sorted(got) == list(range(pushes))
    for start in (0, 100, 200):  # each thread's pushes in the order it sent them
        assert [n for n in got if start <= n < start + 100] == list(range(start, start + 100))
    assert most[0] == 1


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


async def test_pushes_sent_together_go_at_the_blocks_end_in_order_through_one_event_loop(monkeypatch):
    """A stop pushes a status per robot from a thread with no loop of its own: inside live.together() they go at
    the block's end, in their order, through one async_to_sync (a new event loop and Redis connection each cost
    a stop of 100 robots 0.8 s of CPU); nested blocks send with the outer one."""
    layer, group, channel = await _listening()
    through = []
    real = live.async_to_sync
    monkeypatch.setattr(live, "async_to_sync", lambda fn: through.append(fn) or real(fn))
    during = []

    def stop_like() -> None:
        with live.together():
            for n in range(5):
                with live.together():
                    live.send(group, {"type": "test.push", "n": n})
            during.append(len(through))  # nothing handed over yet

    await asyncio.to_thread(stop_like)
    message = await asyncio.wait_for(
        layer.receive(channel), 5
    )  # one message to the group: its readers unpack it
    assert message["type"] == live.BATCH
    assert [push["n"] for push in live.unbatched(message)] == [0, 1, 2, 3, 4]
    assert during == [0] and len(through) == 1


async def test_pushes_sent_together_go_as_one_message_per_group_in_their_order(monkeypatch):
    """A push costs channels_redis about seven round trips whatever its size: a block's pushes to one group go
    as one message (at most BATCH_MAX pushes each), a single push as itself."""
    monkeypatch.setattr(live, "BATCH_MAX", 3)
    pushes = [("fleet", {"n": n}) for n in range(5)] + [("robot.1", {"n": 9})]
    pushes.insert(2, ("robot.2", {"n": 7}))
    sent = live._batched(pushes)
    assert [(group, live.unbatched(message)) for group, message in sent] == [
        ("fleet", [{"n": 0}, {"n": 1}, {"n": 2}]),
        ("fleet", [{"n": 3}, {"n": 4}]),
        ("robot.2", [{"n": 7}]),
        ("robot.1", [{"n": 9}]),
    ]
    assert sent[2][1] == {"n": 7}  # alone: not wrapped
