"""The pose ticks, read once per web process and encoded once for all its dashboards.

The links process publishes one batch of poses per tick to the channel layer's poses group (robots.poses). If
every dashboard socket were a member of that group, each tick would be copied into Redis once per socket, read
back and decoded by each, and encoded again as JSON by each: work that grows as dashboards × robots, which at
hundreds of robots and tens of dashboards is what fell behind first (docs/scale.md, "Measured on the cluster").

Instead each web process (each event loop) has one PoseFanout, the only member of the group for that process.
It reads a tick, encodes it once, and hands the same text to every fleet socket of the process; a robot page gets
its own robot's pose only. A socket still busy sending the previous tick (a slow client) is not waited for: the
ticks it misses meanwhile are merged (the latest pose per robot) and sent as one when it is free, so a slow
client costs its own encoding, never the others' rate.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import weakref

import live

log = logging.getLogger(__name__)

TICK = live.poses([])["type"]  # the message type of a tick of poses
REJOIN_S = 600.0  # renew the group membership well inside channels_redis's group_expiry (a day by default)
_fanouts: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # event loop -> its PoseFanout


def encode(poses: list) -> str:
    """The text of one fleet.poses message, as a consumer's send_json would encode it: strict JSON, never a bare
    NaN or Infinity (JSON.parse in the browser would throw on it). A pose that cannot be said so is left out
    (the gate in robots.poses should have refused it already), never the whole tick."""
    try:
        return json.dumps(live.poses(poses), allow_nan=False)
    except ValueError:
        kept = [pose for pose in poses if _strict(pose)]
        log.error("pose fanout: %d poses with NaN or infinity left out", len(poses) - len(kept))
        return json.dumps(live.poses(kept), allow_nan=False)


def _strict(pose) -> bool:
    try:
        json.dumps(pose, allow_nan=False)
    except ValueError:
        return False
    return True


class _Socket:
    """One subscriber: its consumer, the robot it is limited to (None: all), and what waits to be sent."""

    __slots__ = ("consumer", "robot_id", "sending", "task", "waiting")

    def __init__(self, consumer, robot_id: int | None) -> None:
        self.consumer, self.robot_id = consumer, robot_id
        self.sending = False
        self.task: asyncio.Task | None = None
        self.waiting: dict[int, dict] = {}  # robot id -> latest pose, merged while a send is under way


class PoseFanout:
    """One reader of the poses group for this event loop; subscribe() the sockets that show poses.

    A socket's connect never waits on Redis here: subscribing only starts the reader when none runs, and the
    reader joins the group, reads, and leaves the group by itself. (A connect once waited on a lock held across
    Redis calls; when those hung, the page's socket never took its commands, a stop among them.)
    """

    LEAVE_S = 2.0  # how long the last socket out waits for the reader to leave the group

    def __init__(self, layer) -> None:
        self.layer = layer
        self.sockets: dict[object, _Socket] = {}
        self.reader: asyncio.Task | None = None

    @classmethod
    def of(cls, layer) -> PoseFanout:
        """This event loop's fanout (a web process has one loop; tests may run several in turn)."""
        loop = asyncio.get_running_loop()
        fanout = _fanouts.get(loop)
        if fanout is None or fanout.layer is not layer:
            fanout = _fanouts[loop] = cls(layer)
        return fanout

    async def subscribe(self, consumer, robot_id: int | None = None) -> None:
        """From now on the consumer gets every tick (or its robot's poses in each tick)."""
        self.sockets[consumer] = _Socket(consumer, robot_id)
        if self.reader is None or self.reader.done():
            self.reader = asyncio.ensure_future(self._read())

    async def unsubscribe(self, consumer) -> None:
        """The socket closed; the last one out stops the reader, which leaves the group (waited for, bounded)."""
        self.sockets.pop(consumer, None)
        if self.sockets or self.reader is None:
            return
        reader, self.reader = self.reader, None
        reader.cancel()
        await asyncio.wait({reader}, timeout=self.LEAVE_S)

    async def _read(self) -> None:
        # the layer's default prefix: channels_redis reads a process's channels of one prefix together
        channel = await self.layer.new_channel()
        joined = None  # loop time of the last group_add that went through
        try:
            while True:
                now = asyncio.get_running_loop().time()
                if joined is None or now - joined > REJOIN_S:
                    when = await self._join(channel)
                    if when is None and joined is None:
                        continue  # not in the group yet: nothing would come
                    joined = when or joined
                try:
                    message = await self.layer.receive(channel)
                except asyncio.CancelledError:
                    raise
                except Exception:  # Redis lost for a moment: the ticks resume when it is back
                    log.exception("pose fanout: reading the poses group failed")
                    await asyncio.sleep(1.0)
                    continue
                if message.get("type") == TICK:
                    self.deliver(message.get("poses") or [])
        finally:
            with contextlib.suppress(Exception):  # Redis away: the membership lapses by itself
                await asyncio.wait_for(self.layer.group_discard(live.POSES_GROUP, channel), self.LEAVE_S)

    async def _join(self, channel: str) -> float | None:
        """Join (or renew) the group; the loop time it went through, None when Redis did not answer."""
        try:
            await asyncio.wait_for(self.layer.group_add(live.POSES_GROUP, channel), self.LEAVE_S)
        except asyncio.CancelledError:
            raise
        except Exception:
            log.warning("pose fanout: joining the poses group failed; trying again", exc_info=True)
            await asyncio.sleep(1.0)
            return None
        return asyncio.get_running_loop().time()

    def deliver(self, poses: list) -> None:
        """Hand one tick to every socket: one encoding for all the fleet sockets that are free."""
        text = None
        for socket in list(self.sockets.values()):
            mine = poses if socket.robot_id is None else [p for p in poses if p.get("id") == socket.robot_id]
            if not mine:
                continue
            if socket.sending:
                socket.waiting.update((p["id"], p) for p in mine)
                continue
            if socket.robot_id is None:
                text = text if text is not None else encode(poses)
                out = text
            else:
                out = encode(mine)
            socket.sending = True
            socket.task = asyncio.ensure_future(self._send(socket, out))

    async def _send(self, socket: _Socket, text: str) -> None:
        try:
            while True:
                await socket.consumer.send(text_data=text)
                if not socket.waiting:
                    return
                merged, socket.waiting = list(socket.waiting.values()), {}
                text = encode(merged)  # this slow socket's own catch-up: the latest pose of each robot missed
        except Exception as exc:  # the client went away under the send: its disconnect unsubscribes it
            log.debug("pose fanout: send failed: %s", exc)
        finally:
            socket.sending = False
