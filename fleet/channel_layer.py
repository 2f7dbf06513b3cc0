"""channels_redis' pub/sub channel layer, with subscriptions that survive their connection and a receive that can
time out.

channels_redis 4.3's pub/sub layer holds one Redis connection per event loop for its subscriptions. When that
connection is cut (Redis restarted, a proxy's idle timeout, CLIENT KILL), its receive task logs "Unexpected
exception in receive task" and never subscribes again: every push to that web process is lost from then on, and
its pages go on showing the fleet as it was (tests/fleet/test_channel_layer.py fails on the library's own). Here
the task subscribes again to every channel and group it held, and then hands each of the loop's channels a
RESUBSCRIBED message: what was published in between is lost, so a reader of the pages' pushes (portal.fanout)
sends its pages back to a fresh snapshot.

And the library's receive, cancelled (a timeout: the recorder's `wait_for(receive, 1 s)`), unsubscribes its
channel and drops its queue: what the channel's groups publish before the next receive is lost. Here a channel in
a group is kept until it leaves its last group (group_discard), whatever its receives do; one in no group goes
with its cancelled receive, as in the library (a consumer's own channel, its socket closed).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from channels_redis import pubsub
from channels_redis.utils import _wrap_close, decode_hosts

import live

log = logging.getLogger(__name__)

RESUBSCRIBED = live.RESUBSCRIBED  # the message each channel of a loop gets once it is subscribed again
RETRY_S = 0.5  # between attempts to subscribe again while Redis does not answer


class RedisPubSubChannelLayer(pubsub.RedisPubSubChannelLayer):
    """The channel layer of every process (settings.CHANNEL_LAYERS)."""

    def _get_layer(self):
        loop = asyncio.get_running_loop()
        layer = self._layers.get(loop)
        if layer is None:
            layer = self._layers[loop] = _LoopLayer(*self._args, **self._kwargs, channel_layer=self)
            _wrap_close(self, loop)
        return layer


class _LoopLayer(pubsub.RedisPubSubLoopLayer):
    """One event loop's layer: its shards' subscriptions survive a cut; a channel in a group lives until it
    leaves its last group."""

    def __init__(self, *args, hosts=None, **kwargs) -> None:
        super().__init__(*args, hosts=hosts, **kwargs)
        self._shards = [_Shard(host, self) for host in decode_hosts(hosts)]

    async def receive(self, channel):
        if channel not in self.channels:
            await self._subscribe_to_channel(channel)
        try:
            return self.channel_layer.deserialize(await self.channels[channel].get())
        except asyncio.CancelledError:  # a timeout, or its consumer gone: kept while a group feeds it
            if not self._grouped(channel):
                await self._drop(channel)
            raise

    async def group_discard(self, group, channel):
        await super().group_discard(group, channel)
        if not self._grouped(channel):  # in no group any more: nothing will come to it
            await self._drop(channel)

    def _grouped(self, channel: str) -> bool:
        return any(channel in members for members in self.groups.values())

    async def _drop(self, channel: str) -> None:
        if self.channels.pop(channel, None) is not None:
            await self._get_shard(channel).unsubscribe(channel)


class _Shard(pubsub.RedisSingleShardConnection):
    """One Redis server's connections of one event loop: its receive task survives a cut connection."""

    async def _do_receiving(self) -> None:
        cut = False
        while True:
            try:
                if cut:
                    await self._subscribe_again()
                    cut = False
                    self._tell_resubscribed()
                if self._pubsub is not None and self._pubsub.subscribed:
                    message = await self._pubsub.get_message(ignore_subscribe_messages=True, timeout=0.1)
                    self._receive_message(message)
                else:
                    await asyncio.sleep(0.1)
            except (asyncio.CancelledError, GeneratorExit):
                raise
            except Exception as exc:  # the connection cut, or Redis not answering: subscribe again
                if not cut:
                    log.warning("channel layer: subscriptions lost (%r); subscribing again", exc)
                cut = True
                await asyncio.sleep(RETRY_S)

    async def _subscribe_again(self) -> None:
        """A new subscription connection holding every channel and group this loop held."""
        async with self._lock:
            old, self._pubsub = self._pubsub, None
            if old is not None:
                with contextlib.suppress(Exception):  # its connection is gone already
                    await old.aclose()
            self._ensure_redis()
            self._pubsub = self._redis.pubsub()
            if self._subscribed_to:
                await self._pubsub.subscribe(*self._subscribed_to)
        log.warning("channel layer: subscribed again to %d channels and groups", len(self._subscribed_to))

    def _tell_resubscribed(self) -> None:
        data = self.channel_layer.channel_layer.serialize({"type": RESUBSCRIBED})
        for queue in self.channel_layer.channels.values():
            queue.put_nowait(data)
