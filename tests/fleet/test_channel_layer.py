"""The channel layer (settings.CHANNEL_LAYERS: channels_redis' pub/sub layer) as the pushes use it: a web process's
reader of a group whose Redis connection is cut subscribes again and gets the pushes made after it (a push made
while it is away is not kept for it: the pages start from a snapshot and pose ticks come ten times a second)."""

from __future__ import annotations

import asyncio
import time
import uuid

import pytest
import redis.asyncio as redis
from channels.layers import get_channel_layer
from django.conf import settings

from fleet.channel_layer import RESUBSCRIBED

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(60)]


async def _received(layer, channel, timeout: float) -> dict | None:
    try:
        return await asyncio.wait_for(layer.receive(channel), timeout)
    except TimeoutError:
        return None


async def test_a_group_reader_whose_connection_is_cut_gets_the_pushes_after_it():
    layer = get_channel_layer()
    group = f"cut-{uuid.uuid4().hex[:8]}"
    channel = await layer.new_channel()
    await layer.group_add(group, channel)
    await layer.group_send(group, {"type": "probe", "n": 0})
    assert (await _received(layer, channel, 5))["n"] == 0

    loop_layer = layer._get_layer()  # this loop's; its connection that holds the subscriptions
    shard = loop_layer._get_shard(loop_layer._get_group_channel_name(group))
    host, port = shard._pubsub.connection._writer.get_extra_info("sockname")[:2]
    async with redis.from_url(settings.REDIS_URL) as admin:
        assert await admin.client_kill(f"{host}:{port}")

    seen, n, deadline = [], 0, time.monotonic() + 20
    while not any(m["type"] == "probe" for m in seen) and time.monotonic() < deadline:
        n += 1
        await layer.group_send(group, {"type": "probe", "n": n})
        while (message := await _received(layer, channel, 0.2)) is not None:
            seen.append(message)
    kinds = [m["type"] for m in seen]
    assert "probe" in kinds, f"no push reached the reader in 20 s after its connection was cut ({n} sent)"
    # told first that what was published while it was away is lost (its pages start again from a snapshot)
    assert kinds[0] == RESUBSCRIBED, kinds
    await layer.group_discard(group, channel)


async def test_a_receive_that_timed_out_loses_nothing_published_before_the_next_and_the_last_group_left_ends_it():
    """The recorder waits for a push a second at a time; the library's receive, timed out, unsubscribed its channel,
    and what its groups published before the next receive was lost."""
    layer = get_channel_layer()
    group = f"wait-{uuid.uuid4().hex[:8]}"
    channel = await layer.new_channel()
    await layer.group_add(group, channel)
    assert await _received(layer, channel, 0.1) is None  # timed out
    await layer.group_send(group, {"type": "probe", "n": 1})  # before the next receive
    await asyncio.sleep(0.1)
    assert (await _received(layer, channel, 5))["n"] == 1
    await layer.group_discard(group, channel)
    assert channel not in layer._get_layer().channels  # in no group: its queue and subscription are gone


async def test_a_channel_in_no_group_goes_with_its_cancelled_receive():
    """As in the library: a consumer's own channel (never in a group) is not left subscribed once its socket is
    gone and its receive cancelled."""
    layer = get_channel_layer()
    channel = await layer.new_channel()
    assert await _received(layer, channel, 0.1) is None
    assert channel not in layer._get_layer().channels
