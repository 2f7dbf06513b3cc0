"""One rosbridge client's connection to a simulated endpoint: its subscriptions and its bounded send queue.

The send side of `simworker/server.py`, kept apart from the protocol's operations: each client's frames wait in a
queue of at most SEND_QUEUE drained by the client's own writer task (frames joined into one socket write), a
subscription's throttle and queue_length act as rosbridge's subscription modifiers do (rosbridge_library's
subscription_modifiers.py: a throttle alone drops what comes before its interval ends; a throttle with a
queue_length keeps the newest queue_length messages and lets one go each interval; a queue_length alone bounds
what waits to be sent), and a client that accepts no data for STALL_SECONDS is cut off, so a client that never reads loses
messages without slowing anyone else. Incoming publishes spend a token bucket of FLOOD_RATE a second and
PER_TOPIC_RATE more for each topic the endpoint takes commands on: rosbridge itself drops no publish, and one
client (the portal's link to a shard) may command 500 robots at once, a held button's 5 Hz each and a stop-all's
zeros on top; a bound fixed per client would drop those, where it is meant for a client flooding a topic.
"""

from __future__ import annotations

import asyncio
import logging
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from websockets.asyncio.server import ServerConnection

from simworker import outgoing

log = logging.getLogger("simworker.server")  # one endpoint's lines under one name, as rosbridge logs them

SEND_QUEUE = 1000  # messages waiting for one client; older ones are dropped beyond this
OVERFLOW_LOG_EVERY = 1000  # a client's first message dropped so is logged, then one line per this many
STALL_SECONDS = 5.0  # a client that accepts no data for this long is disconnected
FLOOD_RATE = 2000.0  # publish ops per second per client before the excess is dropped, and
PER_TOPIC_RATE = 50.0  # more for each topic the endpoint takes (a controller's 50 Hz on each robot's cmd_vel)
WRITE_BATCH = 256  # frames joined into one socket write


class Deferred:
    """A frame written only when it is sent, once for every client that sends it. rosbridge's QueueMessageHandler
    holds the ROS message itself and serialises it as it goes out, so a held message that a newer one replaces is
    never written: the links' odometry subscription (a throttle with a queue_length of 1) takes one message in
    two of the simulator's 20 Hz, and the simulator wrote both."""

    __slots__ = ("_build", "_text")

    def __init__(self, build: Callable[[], str]) -> None:
        self._build: Callable[[], str] | None = build
        self._text: str | None = None

    def __call__(self) -> str:
        if self._text is None:
            self._text = self._build()
            self._build = None
        return self._text


@dataclass
class Subscription:
    """One client's subscription to a topic: the ids it was asked under, and what they make of it together. A
    message on the topic asks `due()` at the rate of its publisher, so the throttle, queue_length and compression
    are worked out when an id comes or goes (`add`, `remove`), not for each message."""

    ids: dict[str | None, tuple[int, int]] = field(
        default_factory=dict
    )  # id -> (throttle_rate, queue_length)
    last_sent: float = 0.0
    queued: int = 0
    held: deque = field(default_factory=deque)  # throttle with a queue_length: the newest, waiting their turn
    release: asyncio.TimerHandle | None = None  # when the next held one goes
    compressions: dict[str | None, str] = field(default_factory=dict)  # id -> compression asked for
    # what the ids make together (as rosbridge's Subscription.update_params): the least throttle (s) and queue_length
    throttle: float = 0.0
    queue_length: int = 0
    # a throttle with a queue_length: messages wait their turn (rosbridge's QueueMessageHandler)
    holds: bool = False
    compression: str = "none"  # the one compression all ids get: cbor over png over none

    def add(self, id_: str | None, throttle_rate: int, queue_length: int, compression: str) -> None:
        """Subscribed (again) under this id."""
        self.ids[id_] = (max(throttle_rate, 0), max(queue_length, 0))
        self.compressions[id_] = compression
        self._update()

    def remove(self, id_: str | None) -> None:
        """Unsubscribed under this id (the subscription ends when no id is left)."""
        self.ids.pop(id_, None)
        self.compressions.pop(id_, None)
        self._update()

    def _update(self) -> None:
        self.throttle = min((t for t, _ in self.ids.values()), default=0) / 1000.0
        self.queue_length = min((q for _, q in self.ids.values()), default=0)
        self.holds = bool(self.throttle) and self.queue_length > 0
        asked = set(self.compressions.values())
        self.compression = next((c for c in ("cbor", "png") if c in asked), "none")

    def due(self) -> bool:
        """Whether a message now would be taken: held for its turn, or past its throttle (rosbridge's
        ThrottleMessageHandler drops a throttled one before serialising)."""
        if self.holds:
            return True
        return not (self.throttle and time.monotonic() - self.last_sent < self.throttle)

    def end(self) -> None:
        """Unsubscribed: nothing held goes out any more."""
        self.held.clear()
        if self.release is not None:
            self.release.cancel()
            self.release = None


class Client:
    """One WebSocket connection: its subscriptions, advertisements and bounded send queue."""

    def __init__(self, ws: ServerConnection, topics: int = 0) -> None:
        self.ws = ws
        # topics: those the endpoint takes publishes on
        self.flood_rate = FLOOD_RATE + PER_TOPIC_RATE * topics
        self.id = uuid.uuid4()  # rosbridge names clients by a uuid in its log lines
        self.fragment_size: int | None = None  # set by any incoming message carrying fragment_size
        self.queue: deque[tuple[str | bytes | list[str], Subscription | None]] = deque()
        self.wake = asyncio.Event()
        self.subs: dict[str, Subscription] = {}
        self.adverts: dict[str, set] = {}
        self.dropped = 0
        self.overflowed = 0  # of those, dropped because the send queue was full (the client reads too slowly)
        self.tokens, self.token_time = self.flood_rate, time.monotonic()
        self.connected_at = time.time()
        self.provided: set[str] = set()  # services this client advertised
        self.pending: dict[str, asyncio.Future] = {}  # forwarded calls awaiting its service_response
        self.fragments: dict[str, dict[int, str]] = {}

    def send(self, text: str | bytes | Deferred, sub: Subscription | None = None) -> None:
        """Queue a frame (fragments of it past fragment_size) for the writer; drop the oldest when full."""
        if sub is not None:
            if sub.holds:
                self._hold(text, sub)
                return
            if not sub.due():
                return
            if (qlen := sub.queue_length) and sub.queued >= qlen:
                self.dropped += 1
                return
            sub.last_sent = time.monotonic()
            sub.queued += 1
        self._enqueue(text, sub)

    def _hold(self, text: str | bytes | Deferred, sub: Subscription) -> None:
        """Keep the newest queue_length messages; the oldest is dropped past it; one goes each throttle interval."""
        if sub.held.maxlen != sub.queue_length:
            sub.held = deque(sub.held, maxlen=sub.queue_length)
        if sub.release is None and not sub.held and time.monotonic() - sub.last_sent >= sub.throttle:
            sub.last_sent = time.monotonic()  # its interval is over: it goes at once
            self._enqueue(text, None)
            return
        if len(sub.held) == sub.held.maxlen:
            self.dropped += 1
        sub.held.append(text)
        if sub.release is None:
            wait = max(0.0, sub.last_sent + sub.throttle - time.monotonic())
            sub.release = asyncio.get_running_loop().call_later(wait, self._release, sub)

    def _release(self, sub: Subscription) -> None:
        sub.release = None
        if not sub.held or not sub.ids:
            return
        sub.last_sent = time.monotonic()
        self._enqueue(sub.held.popleft(), None)
        if sub.held:
            sub.release = asyncio.get_running_loop().call_later(sub.throttle, self._release, sub)

    def _enqueue(self, text: str | bytes | Deferred, sub: Subscription | None) -> None:
        if isinstance(text, Deferred):
            text = text()
        if isinstance(text, str) and self.fragment_size and len(text) > self.fragment_size:
            text = outgoing.fragments(text, self.fragment_size)
            log.info("[Client %s] sending %d parts [fragment size: %s; expected duration: ~0s]",
                     self.id, len(text), self.fragment_size)  # fmt: skip
        if len(self.queue) >= SEND_QUEUE:
            _old, old_sub = self.queue.popleft()
            if old_sub is not None:
                old_sub.queued -= 1
            self.overflowed += 1
            self.dropped += 1
            if self.overflowed == 1 or self.overflowed % OVERFLOW_LOG_EVERY == 0:
                # said, not silent: a client reading too slowly loses messages it asked for (a watcher that
                # counts them as never sent would be misled; the operator of a slow console should know)
                log.warning("[Client %s] send queue full (%d messages): the oldest dropped, %d so far",
                            self.id, SEND_QUEUE, self.overflowed)  # fmt: skip
        self.queue.append((text, sub))
        self.wake.set()

    def allow(self) -> bool:
        """Spend one token of the incoming-rate budget; False when flooding."""
        now = time.monotonic()
        self.tokens = min(self.flood_rate, self.tokens + (now - self.token_time) * self.flood_rate)
        self.token_time = now
        if self.tokens < 1:
            return False
        self.tokens -= 1
        return True

    async def writer(self) -> None:
        """Send queued frames in order until the connection closes; cut off a client that stops reading."""
        while True:
            if not self.queue:
                self.wake.clear()
                await self.wake.wait()
                continue
            batch = []
            while self.queue and len(batch) < WRITE_BATCH:
                text, sub = self.queue.popleft()
                if sub is not None:
                    sub.queued -= 1
                batch.extend(text if isinstance(text, list) else [text])
            try:
                async with asyncio.timeout(STALL_SECONDS):
                    await self._write(batch)
            except TimeoutError:
                log.warning("client %s stopped reading; closing its connection", self.ws.remote_address)
                self.ws.transport.abort()
                return

    async def _write(self, batch: list[str | bytes]) -> None:
        """Write frames with one socket write: websockets' send_context pattern, frames joined."""
        ws = self.ws
        async with ws.send_context():
            for text in batch:
                if isinstance(text, bytes):
                    ws.protocol.send_binary(text)
                else:
                    ws.protocol.send_text(text.encode())
            ws.transport.write(b"".join(ws.protocol.data_to_send()))
