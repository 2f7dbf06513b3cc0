"""The pushes of a page's groups, read once per web process and handed to all its sockets there.

Every push to the browsers goes through a channel-layer group: the pose ticks (robots.poses) and the events of
the fleet, of one robot and of the alerts (live). If every page socket were a member of its groups, each push
would be copied into Redis once per socket and read back by each: work that grows as sockets × pushes. At 100
robots and 50 dashboards that was most of the web's time (docs/scale.md, "The cost of a robot"): a stop's 200
status pushes made 10,000 Redis deliveries, a tick of poses was encoded 50 times.

Instead each web process (each event loop) has one reader per group, the only member of the group for that
process, which hands what it reads to the sockets subscribed to it there:

- PoseFanout (the ticks of poses): encoded once for all the fleet sockets of the process; a robot page gets its
  own robot's pose only. A socket still busy sending the previous tick (a slow client) is not waited for: the
  ticks it misses meanwhile are merged (the latest pose per robot) and sent as one when it is free, so a slow
  client costs its own encoding, never the others' rate. A socket only one tick behind (a tick that came before its
  send of the previous one ran: a busy web process) is sent that tick's shared text, not an encoding of its own.
- EventFanout (every other push): each message dispatched to each subscribed consumer, in the order it came, as
  the channel layer would have (its handler by the message's type); the pushes that come within GATHER_S of the
  first go to the page in one frame ({"type": "batch", "messages": [...]}, unpacked by static/fleet/live.js), as
  does what came while a socket's last frame was being sent. A socket's messages wait while its
  snapshot is being sent, and a socket more than BACKLOG messages behind (a client that stopped reading) is
  closed (its page reconnects and starts again from a snapshot) rather than left holding memory for ever.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import logging
import weakref
from collections import deque
from math import isfinite

import orjson

import live

log = logging.getLogger(__name__)

TICK = live.poses([])["type"]  # the message type of a tick of poses
# a page's connect waits this long at most for its groups' reader to join (Redis hung: no more)
JOIN_WAIT_S = 0.25
# join again now and then (a no-op while subscribed; a layer with expiring membership needs it)
REJOIN_S = 600.0
_fanouts: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # event loop -> {(kind, group): reader}


COLUMNS = ("id", "x", "y", "yaw", "v", "w", "t", "battery", "rtt", "fault", "fault_since")  # live.RobotPose's


def encode(poses: list) -> str:
    """The text of one fleet.poses message for the browsers: a row per pose under the tick's columns.

    {"type": "fleet.poses", "at": unix time, "fields": [...], "rows": [[...], ...]}: the fields are those any pose
    of the tick has (COLUMNS' order, then any other in name order), null where a pose has none; `t` is in ms
    after `at`. Half the text of an object per pose: every socket compresses what it is sent (permessage-
    deflate), which was most of what a dashboard costs the web process, in proportion to the text. decode()
    here and static/fleet/live.js make the poses back. Strict JSON, never a bare NaN or Infinity (JSON.parse
    in the browser would throw on it): a pose that cannot be said so is left out (the gate in robots.poses
    should have refused it already), never the whole tick. Written by orjson (a 100-robot tick: 200 -> 138 µs,
    once a tick in every web process), which would write a NaN as null: rows holding one are found first."""
    present = set().union(*poses) if poses else set()
    fields = [f for f in COLUMNS if f in present] + sorted(present.difference(COLUMNS))
    rows = [[pose.get(f) for f in fields] for pose in poses]
    if not all(_finite(row) for row in rows):
        kept = [row for row in rows if _finite(row)]
        log.error("pose fanout: %d poses with NaN or infinity left out", len(rows) - len(kept))
        rows = kept
    at = 0.0
    if "t" in present:
        column = fields.index("t")
        stamps = [row[column] for row in rows if row[column] is not None]
        at = round(min(stamps), 3) if stamps else 0.0
        for row in rows:
            if row[column] is not None:
                row[column] = round((row[column] - at) * 1000)
    return orjson.dumps({"type": TICK, "at": at, "fields": fields, "rows": rows}).decode()


def _finite(row: list) -> bool:
    """No float of the row is NaN or infinite (what JSON cannot say)."""
    return all(isfinite(value) for value in row if value.__class__ is float)


def decode(message: dict) -> list[dict]:
    """The poses of a fleet.poses message as encode() sends it, one dict each (what static/fleet/live.js does)."""
    fields, at = message.get("fields") or [], message.get("at") or 0.0
    poses = []
    for row in message.get("rows") or []:
        pose = {f: value for f, value in zip(fields, row, strict=False) if value is not None}
        if "t" in pose:
            pose["t"] = at + pose["t"] / 1000
        poses.append(pose)
    return poses


class _Socket:
    """One subscriber: its consumer, the robot it is limited to (None: all), and what waits to be sent."""

    __slots__ = ("consumer", "missed", "robot_id", "sending", "task")

    def __init__(self, consumer, robot_id: int | None) -> None:
        self.consumer, self.robot_id = consumer, robot_id
        self.sending = False
        self.task: asyncio.Task | None = None
        self.missed: list[_Tick] = []  # the ticks that came while a send was under way, oldest first


class _Tick:
    """One tick of poses as the fleet sockets get it: encoded once, when a first socket needs its text."""

    __slots__ = ("_text", "poses")

    def __init__(self, poses: list) -> None:
        self.poses, self._text = poses, None

    def text(self) -> str:
        if self._text is None:
            self._text = encode(self.poses)
        return self._text


class GroupReader(abc.ABC):
    """The one member of a channel-layer group for this event loop; subclasses say what a message becomes.

    A socket's connect never waits on Redis here: subscribing only starts the reader when none runs, and the
    reader joins the group, reads, and leaves the group by itself. (A connect once waited on a lock held across
    Redis calls; when those hung, the page's socket never took its commands, a stop among them.)
    """

    LEAVE_S = 2.0  # how long the last socket out waits for the reader to leave the group

    def __init__(self, layer, group: str) -> None:
        self.layer, self.group = layer, group
        self.sockets: dict = {}  # consumer -> what the subclass keeps for it
        self.reader: asyncio.Task | None = None
        self.member = asyncio.Event()  # set once the running reader has joined the group

    @classmethod
    def of(cls, layer, group: str):
        """This event loop's reader of the group (a web process has one loop; tests may run several in turn)."""
        readers = _fanouts.setdefault(asyncio.get_running_loop(), {})
        reader = readers.get((cls, group))
        if reader is None or reader.layer is not layer:
            reader = readers[(cls, group)] = cls(layer, group)
        return reader

    def _add(self, consumer, kept) -> None:
        self.sockets[consumer] = kept
        if self.reader is None or self.reader.done():
            self.member = asyncio.Event()
            self.reader = asyncio.ensure_future(self._read())

    async def joined(self, timeout: float = JOIN_WAIT_S) -> bool:
        """Wait, `timeout` at most, until the reader is a member of the group (at once when it is): a page's
        snapshot sent before that could miss the pushes made meanwhile. False when Redis did not let it join."""
        try:
            await asyncio.wait_for(asyncio.shield(self.member.wait()), timeout)
        except TimeoutError:
            return False
        return True

    async def unsubscribe(self, consumer) -> None:
        """The socket closed; the last one out stops the reader, which leaves the group (waited for, bounded)."""
        self.sockets.pop(consumer, None)
        if self.sockets or self.reader is None:
            return
        reader, self.reader = self.reader, None
        reader.cancel()
        await asyncio.wait({reader}, timeout=self.LEAVE_S)

    @abc.abstractmethod
    def take(self, message: dict) -> None:
        """What one message read from the group becomes (on the loop, never waiting)."""

    async def _read(self) -> None:
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
                    self.member.set()
                try:
                    message = await self.layer.receive(channel)
                except asyncio.CancelledError:
                    raise
                except Exception:  # Redis lost for a moment: the pushes resume when it is back
                    log.exception("%s fanout: reading the group failed", self.group)
                    await asyncio.sleep(1.0)
                    continue
                for one in live.unbatched(message):  # a together() block's pushes come in one message
                    self.take(one)
        finally:
            with contextlib.suppress(Exception):  # Redis away: the membership lapses by itself
                await asyncio.wait_for(self.layer.group_discard(self.group, channel), self.LEAVE_S)

    async def _join(self, channel: str) -> float | None:
        """Join (or renew) the group; the loop time it went through, None when Redis did not answer."""
        try:
            await asyncio.wait_for(self.layer.group_add(self.group, channel), self.LEAVE_S)
        except asyncio.CancelledError:
            raise
        except Exception:
            log.warning("%s fanout: joining the group failed; trying again", self.group, exc_info=True)
            await asyncio.sleep(1.0)
            return None
        return asyncio.get_running_loop().time()


class PoseFanout(GroupReader):
    """The reader of the poses group; subscribe() the sockets that show poses."""

    @classmethod
    def of(cls, layer, group: str = live.POSES_GROUP) -> PoseFanout:
        return super().of(layer, group)

    def __init__(self, layer, group: str = live.POSES_GROUP) -> None:
        super().__init__(layer, group)

    async def subscribe(self, consumer, robot_id: int | None = None) -> None:
        """From now on the consumer gets every tick (or its robot's poses in each tick)."""
        self._add(consumer, _Socket(consumer, robot_id))

    def take(self, message: dict) -> None:
        if message.get("type") == TICK:
            self.deliver(message.get("poses") or [])

    def deliver(self, poses: list) -> None:
        """Hand one tick to every socket: one encoding for all the fleet sockets (those still sending the
        previous tick get the same text after it)."""
        tick = _Tick(poses)
        for socket in list(self.sockets.values()):
            if socket.robot_id is None:
                mine = tick
            else:
                robot_poses = [p for p in poses if p.get("id") == socket.robot_id]
                if not robot_poses:
                    continue
                mine = _Tick(robot_poses)
            if socket.sending:
                socket.missed.append(mine)
                continue
            socket.sending = True
            socket.task = asyncio.ensure_future(self._send(socket, mine.text()))

    async def _send(self, socket: _Socket, text: str) -> None:
        try:
            while True:
                await socket.consumer.send(text_data=text)
                if not socket.missed:
                    return
                missed, socket.missed = socket.missed, []
                if len(missed) == 1:  # one tick behind (it came before this send ran): its shared text
                    text = missed[0].text()
                    continue
                # a slow socket's own catch-up: the latest pose of each robot in the ticks it missed
                merged = {p["id"]: p for tick in missed for p in tick.poses}
                text = encode(list(merged.values()))
        except Exception as exc:  # the client went away under the send: its disconnect unsubscribes it
            log.debug("pose fanout: send failed: %s", exc)
        finally:
            socket.sending = False


class _Queue:
    """One subscriber of an EventFanout: its consumer, its messages not yet dispatched, and whether they wait."""

    __slots__ = ("consumer", "held", "pending", "task")

    def __init__(self, consumer) -> None:
        self.consumer = consumer
        self.held = True  # until its snapshot is out
        self.pending: deque[dict] = deque()
        self.task: asyncio.Task | None = None


class EventFanout(GroupReader):
    """The reader of one group of events (the fleet's, a robot's, the alerts'); subscribe() each page socket of
    the group, then release() it once its snapshot is sent."""

    # Messages a socket may be behind before it is closed: a stuck client must not hold memory for ever, but a
    # fleet's burst (a lease or status push for each of 1,000 robots commanded together) is no reason to close a
    # page. At 1,000 (the channel layer's capacity per channel) such a burst closed the commanding sockets and
    # their commands were lost (bench.cluster, 500 and 1,000 robots).
    BACKLOG = 20_000
    OVERFLOW_CODE = 1013  # "try again later": the page reconnects and starts from a new snapshot
    # What a socket is sent goes in frames of at most FRAME_MAX messages (a lease push for each of 1,000 robots
    # was 1,000 frames to every page, each framed, compressed and written on its own, seconds of a web process for
    # one fleet-wide command).
    FRAME_MAX = 500
    # A push waits this long for the pushes that come with it, to go to each page in one frame: a robot's change
    # is its status, its transition and its task list, pushed one after another and read from Redis one by one,
    # and a dashboard was sent 13 to 26 frames a second of them beside the 10 ticks (bench.cluster, 100 robots
    # under teleop, 2026-11-29): each frame compressed and written on every socket. One timer a group, not one a
    # socket.
    GATHER_S = 0.02

    def __init__(self, layer, group: str) -> None:
        super().__init__(layer, group)
        self._gathering: asyncio.TimerHandle | None = None

    async def subscribe(self, consumer) -> None:
        """From now on the group's messages are kept for the consumer; they are dispatched once released."""
        self._add(consumer, _Queue(consumer))

    async def unsubscribe(self, consumer) -> None:
        queue = self.sockets.get(consumer)
        if queue is not None and queue.task is not None:
            queue.task.cancel()  # its socket is gone: what it had not been sent yet goes with it
        await super().unsubscribe(consumer)

    def release(self, consumer) -> None:
        """The consumer's snapshot is out: dispatch what came since it subscribed, then each message as it comes."""
        queue = self.sockets.get(consumer)
        if queue is not None:
            queue.held = False
            self._drain(queue)

    def take(self, message: dict) -> None:
        if message.get("type") == live.RESUBSCRIBED:  # pushes were lost while the layer's connection was cut
            for queue in list(self.sockets.values()):
                self._close(queue, "pushes lost while Redis was away: a socket is sent back to a snapshot")
            return
        for queue in list(self.sockets.values()):
            if len(queue.pending) >= self.BACKLOG:
                self._overflow(queue)
                continue
            queue.pending.append(message)
        if self._gathering is None:
            self._gathering = asyncio.get_running_loop().call_later(self.GATHER_S, self._gathered)

    def _gathered(self) -> None:
        self._gathering = None
        for queue in list(self.sockets.values()):
            self._drain(queue)

    def _drain(self, queue: _Queue) -> None:
        if not queue.held and queue.pending and (queue.task is None or queue.task.done()):
            queue.task = asyncio.ensure_future(self._dispatch(queue))

    async def _dispatch(self, queue: _Queue) -> None:
        while queue.pending:  # what came while the last frame was sent goes at once, in the next
            messages = [queue.pending.popleft() for _ in range(min(len(queue.pending), self.FRAME_MAX))]
            try:
                if len(messages) > 1:
                    await queue.consumer.dispatch_many(messages)
                else:
                    await queue.consumer.dispatch(messages[0])
            except asyncio.CancelledError:
                raise
            except (
                OSError
            ) as exc:  # the client went away (uvicorn's ClientDisconnected): its disconnect unsubscribes it
                log.debug(
                    "%s fanout: a socket gone with %d pushes unsent: %r", self.group, len(queue.pending), exc
                )
                queue.pending.clear()
                return
            except Exception:  # one handler's failure costs that message on that socket, never the rest
                log.exception(
                    "%s fanout: a %r push failed on one socket", self.group, messages[0].get("type")
                )

    def _overflow(self, queue: _Queue) -> None:
        self._close(queue, f"a socket {len(queue.pending)} messages behind is closed (its page reconnects)")

    def _close(self, queue: _Queue, why: str) -> None:
        """Close the socket with OVERFLOW_CODE: its page reconnects and starts from a new snapshot."""
        log.warning("%s fanout: %s", self.group, why)
        self.sockets.pop(queue.consumer, None)
        queue.pending.clear()
        closing = asyncio.ensure_future(queue.consumer.close(code=self.OVERFLOW_CODE))
        closing.add_done_callback(_quiet)


def _quiet(task: asyncio.Task) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.debug("fanout: closing a socket failed: %r", task.exception())
