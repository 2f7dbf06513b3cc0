"""An asyncio rosbridge v2 client on `websockets`.

Why not roslibpy: its default transport runs Twisted's reactor in a thread, started once per process; on
Twisted `terminate()` is final, so a long-lived worker that must drop and re-open links cannot use it, and a
process that imported daphne is already tied to Twisted (stack-notes: "roslibpy transports"). The link
process, the registration engine and the execution engine each hold many endpoints in one process; here each
endpoint is one coroutine-driven connection on the caller's event loop: no reactor, no thread per endpoint,
and reconnection (exponential backoff, re-subscribe, re-advertise) is ours to control and test. The wire
format is roslibpy's (robots/rosbridge/codec.py, checked against roslibpy in tests/robots/test_wire_format.py).
"""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable
from dataclasses import dataclass, field

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus, InvalidURI
from websockets.protocol import State

from robots import limits
from robots.rosbridge import codec
from robots.rosbridge.errors import (
    BadFrame,
    FrameTooLarge,
    LinkDown,
    NotRosbridgeError,
    RosbridgeError,
    RosbridgeTimeout,
    ServiceError,
    UnreachableError,
)
from robots.rosbridge.inflow import Inflow

log = logging.getLogger("robots.rosbridge")
STABLE = 2.0  # s: a connection that lasted less is a flap, and the next attempt waits out the backoff
LOGGED_DROPS = 10  # bad frames logged one by one per client; after that one line per thousand
CLOSE_NOT_ROSBRIDGE = 1003  # WebSocket close code "unsupported data"
# Frames read ahead of the reader (websockets' default): memory is bounded by MAX_QUEUE x the frame limit.
MAX_QUEUE = 16
KEEPALIVE_TIMEOUT = "keepalive ping timeout"  # the reason websockets closes a link with when no pong came


# A subscription that wants one message each period asks rosbridge for this share of the period as its throttle_rate,
# with queue_length 0 (throttle_for).
THROTTLE_SHARE = 0.75


def throttle_for(period_ms: int) -> int:
    """The throttle_rate (ms) of a subscription that wants at most one message each period_ms, the freshest: asked
    with queue_length 0, rosbridge's ThrottleMessageHandler drops a message inside the throttle before it is
    serialised and sends the first one past it as it arrives. With a queue_length, its QueueMessageHandler would
    hold every message instead (serialised, on a timer) and send one up to a publishing period old. Three quarters
    of the period, not all of it: a publisher at a multiple of the rate (a TurtleBot's 20 Hz odometry for 10 Hz)
    then has every k-th message pass though it comes a few ms early (at the full period, one early by a
    millisecond is dropped and the next waited for: 6.7 Hz instead of 10)."""
    return max(1, round(period_ms * THROTTLE_SHARE))


@dataclass(eq=False)
class Subscription:
    """A handle returned by subscribe(); pass it to unsubscribe()."""

    topic: str
    type: str
    callback: Callable[[dict], None]
    message: dict
    hz: float = 0.0  # what its throttle lets through at most; 0: no fixed rate

    @property
    def id(self) -> str:
        return self.message["id"]


@dataclass(eq=False)
class ActionGoal:
    """A ROS 2 action goal in flight: `await goal.wait()` gives {"status", "values"}."""

    id: str
    action: str
    result: asyncio.Future
    on_feedback: Callable[[dict], None] | None = None
    feedback: list = field(default_factory=list)

    async def wait(self, timeout: float | None = None) -> dict:
        try:
            return await asyncio.wait_for(asyncio.shield(self.result), timeout)
        except TimeoutError:
            raise RosbridgeTimeout(f"{self.action}: no action result within {timeout:g} s") from None


def _os_reason(exc: OSError) -> str:
    """A short reason for a failed connect: refused, unknown host, or the OS's words."""
    if isinstance(exc, ConnectionRefusedError) or "Connect call failed" in str(exc):
        return "connection refused"
    if isinstance(exc, socket.gaierror):
        return "unknown host"
    return exc.strerror or str(exc)


class RosbridgeClient:
    """One rosbridge connection: service calls, topics, ROS 2 actions, optional reconnection."""

    def __init__(
        self,
        url: str,
        connect_timeout: float = 2.0,
        call_timeout: float = 3.0,
        reconnect: bool = False,
        ping_interval: float | None = 5.0,
        ping_timeout: float | None = None,  # None: the interval
        min_backoff: float = 0.1,
        max_backoff: float = 1.6,
        max_frame_bytes: int | None = None,
    ) -> None:
        self.url = url
        self.max_frame_bytes = max_frame_bytes or limits.current().frame_bytes
        self.connect_timeout, self.call_timeout = connect_timeout, call_timeout
        self.reconnect, self.ping_interval = reconnect, ping_interval
        self.ping_timeout = ping_interval if ping_timeout is None else ping_timeout
        self.min_backoff, self.max_backoff = min_backoff, max_backoff
        self.last_error = ""
        # True once a rosbridge op arrived (even a bad one): something that speaks rosbridge is there
        self.answered = False
        self._ws: ClientConnection | None = None
        self._ids = codec.Ids()
        self._calls: dict[str, asyncio.Future] = {}
        self._goals: dict[str, ActionGoal] = {}
        self._topics: dict[str, list[Subscription]] = {}
        self._adverts: dict[str, dict] = {}
        self._fragments = codec.Fragments(self.max_frame_bytes)
        self._dropped = 0
        self.inflow = Inflow(url, limits.current().frames_per_s)  # frames beyond its rate are dropped unread
        self._link_callbacks: list[Callable[[bool, str], None]] = []
        self._up: bool | None = None
        self._garbage: NotRosbridgeError | None = None
        self._reader: asyncio.Task | None = None
        self._supervisor: asyncio.Task | None = None
        self._closing = False
        self._handlers = {
            "publish": self._on_publish,
            "service_response": self._on_service_response,
            "action_feedback": self._on_action_feedback,
            "action_result": self._on_action_result,
            "fragment": self._on_fragment,
        }

    # ----- connection -----
    @property
    def is_connected(self) -> bool:
        return self._ws is not None

    @property
    def idle(self) -> bool:
        """Connected, with nothing of ours still waiting to be written: a send now goes out at once."""
        ws = self._ws
        return ws is not None and not ws.transport.get_write_buffer_size()

    @property
    def closed(self) -> bool:
        """Closed for good (close() was called): it will not reconnect."""
        return self._closing

    def on_link(self, callback: Callable[[bool, str], None]) -> None:
        """Call callback(up, reason) whenever the link goes up or down."""
        self._link_callbacks.append(callback)

    async def connect(self) -> None:
        """Open the WebSocket once; raise a RosbridgeError with a one-line reason."""
        ws = await self._open()
        self._ws, self._garbage = ws, None
        self._fragments = codec.Fragments(self.max_frame_bytes)
        self._reader = asyncio.create_task(self._read(ws))
        for message in [
            *self._adverts.values(),
            *(s.message for subs in self._topics.values() for s in subs),
        ]:
            await self._send(message)
        self._set_link(True, "connected")

    async def start(self) -> None:
        """Keep the link up in the background: connect, and reconnect with backoff after every drop."""
        self.reconnect = True
        if self._supervisor is None:
            self._supervisor = asyncio.create_task(self._supervise())

    async def wait_connected(self, timeout: float) -> bool:
        """Wait until the link is up (for start()ed clients); False on timeout."""
        deadline = asyncio.get_running_loop().time() + timeout
        while self._ws is None and asyncio.get_running_loop().time() < deadline:
            await asyncio.sleep(0.02)
        return self._ws is not None

    async def close(self) -> None:
        """Close for good: stop reconnecting, fail whatever waits."""
        self._closing = True
        # Taken first: cancelling the supervisor cancels the reader, which forgets the socket it read.
        ws, self._ws = self._ws, None
        if self._supervisor is not None:
            self._supervisor.cancel()
            await _ended(self._supervisor)
        if ws is not None:
            await ws.close()
        if self._reader is not None:
            await _ended(self._reader)
        self._fail_waiting(LinkDown(f"{self.url}: closed"))

    async def round_trip(self, timeout: float = 2.0) -> float:
        """Seconds a WebSocket ping takes to come back (the link's round trip); LinkDown when it cannot."""
        ws = self._ws
        if ws is None:
            raise LinkDown(f"{self.url}: not connected")
        started = asyncio.get_running_loop().time()
        try:
            pong = await ws.ping()
            await asyncio.wait_for(pong, timeout)
        except (TimeoutError, ConnectionClosed) as exc:
            raise LinkDown(f"{self.url}: no pong ({exc.__class__.__name__})") from None
        return asyncio.get_running_loop().time() - started

    async def __aenter__(self) -> RosbridgeClient:
        await self.connect()
        return self

    async def __aexit__(self, *exc) -> None:
        await self.close()

    async def _open(self) -> ClientConnection:
        try:
            return await connect(
                self.url,
                open_timeout=self.connect_timeout,
                compression=None,
                proxy=None,
                max_size=self.max_frame_bytes,
                max_queue=MAX_QUEUE,
                ping_interval=self.ping_interval,
                ping_timeout=self.ping_timeout,
                close_timeout=1.0,
            )
        except (InvalidURI, ValueError):  # ValueError: a port outside 0-65535
            raise RosbridgeError(f"{self.url}: not a WebSocket URL (expected ws://host:port)") from None
        except InvalidStatus as exc:
            status = exc.response.status_code
            raise NotRosbridgeError(
                f"{self.url}: not a rosbridge server (HTTP {status}, no WebSocket)"
            ) from None
        except InvalidHandshake as exc:
            raise NotRosbridgeError(f"{self.url}: not a rosbridge server ({exc})") from None
        except TimeoutError:
            raise RosbridgeTimeout(
                f"{self.url}: no WebSocket handshake within {self.connect_timeout:g} s"
            ) from None
        except OSError as exc:
            raise UnreachableError(f"{self.url}: unreachable ({_os_reason(exc)})") from None

    async def _supervise(self) -> None:
        """Connect, wait for the link to drop, reconnect; nothing one endpoint does ends this loop."""
        loop = asyncio.get_running_loop()
        delay = self.min_backoff
        while not self._closing:
            try:
                await self.connect()
            except Exception as exc:  # a RosbridgeError, or anything else an endpoint made us raise
                self.last_error = str(exc) if isinstance(exc, RosbridgeError) else f"{self.url}: {exc!r}"
                if not isinstance(exc, RosbridgeError):
                    log.exception("%s: connect failed unexpectedly", self.url)
                self._set_link(False, self.last_error)
                await asyncio.sleep(delay)
                delay = min(delay * 2, self.max_backoff)
                continue
            started = loop.time()
            await _ended(self._reader)  # a reader cancelled alone is a drop like any other: reconnect
            if loop.time() - started >= STABLE:
                delay = self.min_backoff
            elif not self._closing:  # a link that drops at once (a hostile endpoint) must not spin
                await asyncio.sleep(delay)
                delay = min(delay * 2, self.max_backoff)

    async def _read(self, ws: ClientConnection) -> None:
        """Hand each frame to _dispatch; one frame can end the link (garbage, oversize), never the reader's loop."""
        reason, error_type = "connection closed", LinkDown
        try:
            async for raw in ws:
                if not self.inflow.admit():
                    continue  # a flood: dropped unread, counted, said (robots.rosbridge.inflow)
                try:
                    self._dispatch(raw)
                except NotRosbridgeError as exc:
                    if not self.reconnect:  # a one-shot client (registration): refuse what follows
                        self._garbage = exc
                        self._fail_waiting(exc)
                        continue
                    log.warning("%s; closing the link to reconnect", exc)
                    reason = "it sent a frame that is not rosbridge"
                    await ws.close(CLOSE_NOT_ROSBRIDGE, "not rosbridge")
                    break
                except Exception:
                    log.exception("%s: a frame broke its handler; dropped", self.url)
        except ConnectionClosed as exc:
            reason, error_type = _closed_reason(exc, self.max_frame_bytes, self.ping_timeout)
        except Exception as exc:
            log.exception("%s: the reader failed", self.url)
            reason = f"reader failed ({exc!r})"
        finally:
            if self._ws is ws:
                self._ws = None
            self._fail_waiting(error_type(f"{self.url}: {reason}"))
            if not self._closing:
                self._set_link(False, reason)

    def _set_link(self, up: bool, reason: str) -> None:
        if self._up == up:
            return
        self._up = up
        for callback in list(self._link_callbacks):
            try:
                callback(up, reason)
            except Exception:
                log.exception("%s: link callback failed", self.url)

    def _fail_waiting(self, error: RosbridgeError) -> None:
        for fut in [*self._calls.values(), *(g.result for g in self._goals.values())]:
            if not fut.done():
                fut.set_exception(error)
        self._goals.clear()

    # ----- incoming -----
    def _dispatch(self, raw: str | bytes) -> None:
        """Route one frame by its op; a frame whose fields are wrong is dropped, failing at most its own call."""
        try:
            message = codec.decode(raw)
        except NotRosbridgeError as exc:
            raise NotRosbridgeError(f"{self.url}: not a rosbridge server ({exc})") from None
        handler = self._handlers.get(message["op"])
        if handler is None:
            return
        self.answered = True
        try:
            handler(codec.check(message))
        except BadFrame as exc:
            self._drop(message, exc)

    def _drop(self, message: dict, exc: RosbridgeError) -> None:
        """Log a bad frame (the first few, then one line per thousand) and fail the call it answers, if any."""
        self._dropped += 1
        if self._dropped <= LOGGED_DROPS or self._dropped % 1000 == 0:
            log.warning("%s: dropped a bad frame (%s); %d so far", self.url, exc, self._dropped)
        key = message.get("id")
        waiting = self._calls.get(key) if isinstance(key, str) else None
        if waiting is not None and not waiting.done():
            waiting.set_exception(type(exc)(f"{self.url}: answered a bad frame ({exc})"))

    def _on_publish(self, message: dict) -> None:
        for sub in self._topics.get(message["topic"], ()):
            try:
                sub.callback(message["msg"])
            except Exception:
                log.exception("%s: callback for %s failed", self.url, sub.topic)

    def _on_service_response(self, message: dict) -> None:
        fut = self._calls.get(message["id"])
        if fut is None or fut.done():
            return
        values = message.get("values")
        if message.get("result") is False:
            fut.set_exception(ServiceError(codec.clip(values)))
        else:
            fut.set_result(values if isinstance(values, dict) else {})

    def _on_action_feedback(self, message: dict) -> None:
        goal = self._goals.get(message["id"])
        if goal is None or goal.on_feedback is None:
            return
        try:
            goal.on_feedback(message.get("values", {}))
        except Exception:
            log.exception("%s: feedback callback for %s failed", self.url, goal.action)

    def _on_action_result(self, message: dict) -> None:
        goal = self._goals.pop(message["id"], None)
        if goal is None or goal.result.done():
            return
        if message.get("result") is False:
            goal.result.set_exception(ServiceError(codec.clip(message.get("values"))))
        else:
            goal.result.set_result({"status": message.get("status"), "values": message.get("values", {})})

    def _on_fragment(self, message: dict) -> None:
        """Reassemble; a message too large for the frame limit fails the call it answers (same id)."""
        try:
            whole = self._fragments.add(message)
        except FrameTooLarge as exc:
            self._drop(message, exc)
            return
        if whole is not None:
            self._dispatch(codec.encode(whole))

    # ----- outgoing -----
    async def _send(self, message: dict) -> None:
        if self._garbage is not None:
            raise self._garbage
        ws = self._ws
        if ws is None:
            raise LinkDown(f"{self.url}: not connected")
        text = codec.encode(message)
        if ws.protocol.state is State.OPEN and not ws.transport.get_write_buffer_size():
            # An open link with nothing waiting (RosbridgeClient.idle): the frame is written at once, as
            # websockets' send would, without its send context and fragment lock (never needed: nothing here
            # sends a message in fragments). A held button's command and a stop's zero take this path; about
            # half of send()'s time for a small frame (docs/benchmarks.md, the portal's hop).
            ws.protocol.send_text(text.encode())
            ws.transport.write(b"".join(ws.protocol.data_to_send()))
            return
        try:  # connecting, closing or backed up: websockets' send waits for the buffer or says it closed
            await ws.send(text)
        except ConnectionClosed:
            raise LinkDown(f"{self.url}: connection lost") from None

    async def call_service(self, name: str, args: dict | None = None, timeout: float | None = None) -> dict:
        """Call a service; ServiceError with the server's text on failure, RosbridgeTimeout if silent."""
        message = codec.call_service(self._ids, name, args)
        fut = asyncio.get_running_loop().create_future()
        self._calls[message["id"]] = fut
        limit = self.call_timeout if timeout is None else timeout
        dropped = self._dropped
        try:
            await self._send(message)
            return await asyncio.wait_for(fut, limit)
        except TimeoutError as exc:
            if isinstance(exc, RosbridgeError):
                raise
            if self._dropped > dropped:  # it did answer, with frames we could not use (logged)
                raise RosbridgeTimeout(
                    f"{self.url}: only bad frames within {limit:g} s of calling {name} "
                    f"({self._dropped - dropped} dropped)"
                ) from None
            raise RosbridgeTimeout(f"{self.url}: no answer to {name} within {limit:g} s") from None
        finally:
            self._calls.pop(message["id"], None)

    async def subscribe(
        self,
        topic: str,
        type_: str,
        callback: Callable[[dict], None],
        throttle_rate: int = 0,
        queue_length: int = 0,
    ) -> Subscription:
        """Subscribe; the subscription is renewed after every reconnection."""
        sub = Subscription(
            topic,
            type_,
            callback,
            codec.subscribe(self._ids, topic, type_, throttle_rate, queue_length),
            hz=1000.0 / throttle_rate if throttle_rate > 0 else 0.0,
        )
        self._topics.setdefault(topic, []).append(sub)
        self.inflow.expect(sub.hz)  # what we asked for is no flood
        if self._ws is not None or not self.reconnect:
            await self._send(sub.message)
        return sub

    async def unsubscribe(self, sub: Subscription) -> None:
        subs = self._topics.get(sub.topic, [])
        if sub in subs:
            subs.remove(sub)
            self.inflow.expect(-sub.hz)
            if not subs:
                self._topics.pop(sub.topic, None)
            if self._ws is not None:
                await self._send(codec.unsubscribe(sub.id, sub.topic))

    async def advertise(self, topic: str, type_: str, latch: bool = False, queue_size: int = 100) -> None:
        """Advertise once per topic; re-advertised after every reconnection."""
        if topic in self._adverts:
            return
        message = codec.advertise(self._ids, topic, type_, latch, queue_size)
        self._adverts[topic] = message
        if self._ws is not None or not self.reconnect:
            await self._send(message)

    async def unadvertise(self, topic: str) -> None:
        message = self._adverts.pop(topic, None)
        if message is not None and self._ws is not None:
            await self._send(codec.unadvertise(message["id"], topic))

    async def publish(self, topic: str, msg: dict, type_: str | None = None) -> None:
        """Publish; with a type the topic is advertised first (once), as roslibpy does."""
        if type_ is not None and topic not in self._adverts:
            await self.advertise(topic, type_)
        await self._send(codec.publish(self._ids, topic, msg))

    async def send_action_goal(
        self, action: str, action_type: str, goal: dict, on_feedback: Callable[[dict], None] | None = None
    ) -> ActionGoal:
        """Send a ROS 2 action goal (rosbridge ros2 branch); await .wait() for its result."""
        message = codec.send_action_goal(self._ids, action, action_type, goal, feedback=True)
        handle = ActionGoal(message["id"], action, asyncio.get_running_loop().create_future(), on_feedback)
        self._goals[handle.id] = handle
        try:
            await self._send(message)
        except RosbridgeError:
            self._goals.pop(handle.id, None)
            raise
        return handle

    async def cancel_action_goal(self, goal: ActionGoal) -> None:
        await self._send(codec.cancel_action_goal(goal.id, goal.action))


def _closed_reason(
    exc: ConnectionClosed, max_frame_bytes: int, keepalive_s: float | None = None
) -> tuple[str, type[LinkDown]]:
    """Why a connection closed, in words; a frame over our limit (we closed with 1009) is FrameTooLarge."""
    if exc.sent is not None and exc.sent.code == 1009:
        return (
            f"it sent a frame larger than the {limits.megabytes(max_frame_bytes)} limit "
            f"({limits.FRAME_SETTING}); link closed",
            FrameTooLarge,
        )
    if exc.sent is not None and exc.sent.reason == KEEPALIVE_TIMEOUT:
        # no pong within the timeout: the endpoint does not read what we send (frozen, cut off, or so far behind
        # that a command or a stop would not reach it in time either), whatever it still sends us
        return f"no answer to a keepalive ping within {keepalive_s:g} s", LinkDown
    return f"connection lost ({exc.rcvd.code if exc.rcvd else 'no close frame'})", LinkDown


async def _ended(task: asyncio.Task) -> None:
    """Wait for task to end, its cancellation included; but if the caller is the one cancelled, that goes on.

    An error the task ended with is logged, never re-raised: a link's supervisor outlives any one reader.
    """
    try:
        await task
    except asyncio.CancelledError:
        if asyncio.current_task().cancelling():
            raise  # the caller is cancelled (a close, or its loop shutting down)
    except Exception:
        log.exception("%s ended with an error", task.get_name())
