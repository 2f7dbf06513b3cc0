"""A rosbridge v2 WebSocket server for one simulated endpoint (asyncio + websockets).

Faithful to docs/reference/rosbridge_protocol.md §2-4 and §7: the server never sends `status`,
`png` or `fragment` ops; bad input is logged and dropped, only a failed service call answers
(`result: false` with the error text). Every client has a bounded send queue drained by its own writer
task, so a client that never reads loses messages (and is cut off) without slowing anyone else.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from simworker import rosapi
from simworker.graph import Graph, ServiceError

log = logging.getLogger("simworker.server")

MAX_MESSAGE_SIZE = 10_000_000  # rosbridge's max_message_size; bigger frames close the connection (1009)
SEND_QUEUE = 1000  # messages waiting for one client; older ones are dropped beyond this
STALL_SECONDS = 5.0  # a client that accepts no data for this long is disconnected
FLOOD_RATE = 2000.0  # publish ops per second per client before the excess is dropped
SERVICE_TIMEOUT = 10.0  # a client-provided service that does not answer fails after this
MAX_FRAGMENTS = 10_000
WRITE_BATCH = 256  # frames joined into one socket write
BRIDGE_NODE = "/rosbridge_websocket"


class BadMessage(Exception):
    """An incoming message the server drops (logged, never answered, as rosbridge does)."""


@dataclass
class Subscription:
    ids: dict[str | None, tuple[int, int]] = field(
        default_factory=dict
    )  # id -> (throttle_rate, queue_length)
    last_sent: float = 0.0
    queued: int = 0

    @property
    def throttle(self) -> float:
        return min(t for t, _ in self.ids.values()) / 1000.0

    @property
    def queue_length(self) -> int:
        return min(q for _, q in self.ids.values())


class Client:
    """One WebSocket connection: its subscriptions, advertisements and bounded send queue."""

    def __init__(self, ws: ServerConnection) -> None:
        self.ws = ws
        self.queue: deque[tuple[str, Subscription | None]] = deque()
        self.wake = asyncio.Event()
        self.subs: dict[str, Subscription] = {}
        self.adverts: dict[str, set] = {}
        self.dropped = 0
        self.tokens, self.token_time = FLOOD_RATE, time.monotonic()
        self.connected_at = time.time()
        self.provided: set[str] = set()  # services this client advertised
        self.pending: dict[str, asyncio.Future] = {}  # forwarded calls awaiting its service_response
        self.fragments: dict[str, dict[int, str]] = {}

    def send(self, text: str, sub: Subscription | None = None) -> None:
        """Queue a frame for the writer; drop the oldest when the queue is full."""
        if sub is not None:
            if sub.ids and (throttle := sub.throttle) and time.monotonic() - sub.last_sent < throttle:
                return
            if (qlen := sub.queue_length if sub.ids else 0) and sub.queued >= qlen:
                self.dropped += 1
                return
            sub.last_sent = time.monotonic()
            sub.queued += 1
        if len(self.queue) >= SEND_QUEUE:
            _old, old_sub = self.queue.popleft()
            if old_sub is not None:
                old_sub.queued -= 1
            self.dropped += 1
        self.queue.append((text, sub))
        self.wake.set()

    def allow(self) -> bool:
        """Spend one token of the incoming-rate budget; False when flooding."""
        now = time.monotonic()
        self.tokens = min(FLOOD_RATE, self.tokens + (now - self.token_time) * FLOOD_RATE)
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
                batch.append(text)
            try:
                async with asyncio.timeout(STALL_SECONDS):
                    await self._write(batch)
            except TimeoutError:
                log.warning("client %s stopped reading; closing its connection", self.ws.remote_address)
                self.ws.transport.abort()
                return

    async def _write(self, batch: list[str]) -> None:
        """Write frames with one socket write: websockets' send_context pattern, frames joined."""
        ws = self.ws
        async with ws.send_context():
            for text in batch:
                ws.protocol.send_text(text.encode())
            ws.transport.write(b"".join(ws.protocol.data_to_send()))


class RosbridgeServer:
    """Serve one endpoint's graph over rosbridge v2."""

    def __init__(self, key: str, graph: Graph, port: int) -> None:
        self.key = key
        self.graph = graph
        self.port = port
        self.clients: set[Client] = set()
        self.subscribers: dict[str, dict[Client, Subscription]] = {}
        self.latched: dict[str, str] = {}
        self.actions: dict[str, tuple[str, Callable]] = {}
        self._server = None
        rosapi.install(graph, port)
        self.ops = {
            "advertise": self._advertise,
            "unadvertise": self._unadvertise,
            "publish": self._publish,
            "subscribe": self._subscribe,
            "unsubscribe": self._unsubscribe,
            "call_service": self._call_service,
            "advertise_service": self._advertise_service,
            "unadvertise_service": self._unadvertise_service,
            "service_response": self._service_response,
            "fragment": self._fragment,
        }
        if graph.ros_version == 2:
            self.ops.update(
                send_action_goal=self._send_action_goal, cancel_action_goal=self._cancel_action_goal
            )
        self.goals: dict[str, ActionGoal] = {}
        self._tasks: set[asyncio.Task] = set()

    # ----- lifecycle -----
    async def start(self, host: str) -> None:
        """Listen on host:port (port 0 picks a free one) and publish the latched bridge topics."""
        self._server = await serve(
            self._handle,
            host,
            self.port,
            max_size=MAX_MESSAGE_SIZE,
            max_queue=64,
            compression=None,
            ping_interval=20,
            ping_timeout=20,
        )
        self.port = self._server.sockets[0].getsockname()[1]
        self._client_topics()

    async def stop(self) -> None:
        """Close the listener and drop every connection at once (no waiting on stalled clients)."""
        for client in list(self.clients):
            client.ws.transport.abort()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()

    # ----- publishing from the simulator -----
    def subscribed(self, topic: str) -> bool:
        """Tell whether any client listens on topic (cheap; publishers check it first)."""
        return topic in self.subscribers

    def publish(self, topic: str, msg: dict) -> None:
        """Publish a message dict on topic (latched topics keep it for later subscribers)."""
        if topic in self.subscribers or topic in self.graph.latched_topics:
            self.publish_text(topic, json.dumps(msg, separators=(",", ":")))

    def publish_text(self, topic: str, msg_json: str) -> None:
        """Publish an already-encoded message body on topic."""
        text = f'{{"op":"publish","topic":"{topic}","msg":{msg_json}}}'
        if topic in self.graph.latched_topics:
            self.latched[topic] = text
        for client, sub in self.subscribers.get(topic, {}).items():
            client.send(text, sub)

    def add_action(self, name: str, type_: str, handler: Callable) -> None:
        """Serve a ROS 2 action through send_action_goal: handler(goal) is called with an ActionGoal."""
        self.actions[name] = (type_, handler)

    # ----- connections -----
    async def _handle(self, ws: ServerConnection) -> None:
        client = Client(ws)
        self.clients.add(client)
        self._client_topics()
        writer = asyncio.create_task(client.writer())
        try:
            async for raw in ws:
                self.dispatch(client, raw)
                await asyncio.sleep(0)  # let the physics and other clients run between messages
        except ConnectionClosed:
            pass
        finally:
            writer.cancel()
            self._drop_client(client)

    def _drop_client(self, client: Client) -> None:
        self.clients.discard(client)
        for topic in list(client.subs):
            self._remove_sub(client, topic)
        for topic in list(client.adverts):
            self._remove_advert(client, topic)
        for goal_id in [g for g, goal in self.goals.items() if goal.client is client]:
            self.goals.pop(goal_id).cancel()
        for service in list(client.provided):
            self._remove_service(client, service)
        for future in client.pending.values():
            future.cancel()
        self._client_topics()

    def _client_topics(self) -> None:
        """Publish the latched /client_count and /connected_clients as rosbridge does."""
        self.publish("/client_count", {"data": len(self.clients)})
        clients = [
            {"ip_address": str(c.ws.remote_address[0]), "connection_time": self.graph.stamp(c.connected_at)}
            for c in self.clients
        ]
        self.publish("/connected_clients", {"clients": clients})

    def dispatch(self, client: Client, raw: str | bytes) -> None:
        """Decode one frame and run its op; anything wrong is logged and dropped."""
        try:
            if isinstance(raw, bytes):
                raw = raw.decode("utf-8")
            msg = json.loads(raw)
            if not isinstance(msg, dict):
                raise BadMessage("message is not a JSON object")
            op = msg.get("op")
            handler = self.ops.get(op) if isinstance(op, str) else None
            if handler is None:
                raise BadMessage(f"Unknown operation: {op}.  Allowed operations: {sorted(self.ops)}")
            if op == "publish" and not client.allow():
                client.dropped += 1  # a publish flood: the excess is dropped
                return
            handler(client, msg)
        except (BadMessage, ValueError, UnicodeDecodeError) as exc:
            log.info("%s: dropped message: %s", self.key, exc)
        except Exception:  # a bug in a handler must not take the endpoint down
            log.exception("%s: error handling message", self.key)

    # ----- ops -----
    def _advertise(self, client: Client, msg: dict) -> None:
        topic, type_ = _name(msg, "topic"), _field(msg, "type", str)
        known = self.graph.topic_types.get(topic)
        if known and _norm(known) != _norm(type_):
            raise BadMessage(
                f"advertise: Tried to register topic {topic} with type {type_} but it is already"
                f" established with type {known}"
            )
        client.adverts.setdefault(topic, set()).add(msg.get("id"))
        self.graph.add_publisher(BRIDGE_NODE, topic, known or self.graph.msg_type(type_))
        if _field(msg, "latch", bool, required=False):
            self.graph.latched_topics.add(topic)

    def _unadvertise(self, client: Client, msg: dict) -> None:
        topic = _name(msg, "topic")
        ids = client.adverts.get(topic)
        if ids is None:
            return
        ids.discard(msg.get("id"))
        if not ids or "id" not in msg:
            self._remove_advert(client, topic)

    def _remove_advert(self, client: Client, topic: str) -> None:
        client.adverts.pop(topic, None)
        if not any(topic in c.adverts for c in self.clients if c is not client):
            self.graph.node(BRIDGE_NODE).pubs.discard(topic)

    def _publish(self, client: Client, msg: dict) -> None:
        topic = _name(msg, "topic")
        body = msg.get("msg", {})
        if not isinstance(body, dict):
            raise BadMessage(f"publish: Expected field msg to be an object. Invalid value: {body!r}")
        if topic not in self.graph.topic_types:
            raise BadMessage(
                f"publish: Cannot infer topic type for topic {topic} as it is not yet advertised"
            )
        if topic not in client.adverts:
            client.adverts[topic] = {None}
            self.graph.add_publisher(BRIDGE_NODE, topic, self.graph.topic_types[topic])
        for handler in self.graph.topic_handlers.get(topic, ()):
            try:
                handler(body)
            except (KeyError, TypeError, ValueError, AttributeError) as exc:
                log.info("%s: %s: message dropped: %s", self.key, topic, exc)
                return
        self.publish(topic, body)

    def _subscribe(self, client: Client, msg: dict) -> None:
        topic = _name(msg, "topic")
        type_ = _field(msg, "type", str, required=False)
        throttle = _field(msg, "throttle_rate", int, required=False) or 0
        qlen = _field(msg, "queue_length", int, required=False) or 0
        if topic not in self.graph.topic_types:
            if not type_:
                raise BadMessage(f"subscribe: Cannot subscribe to {topic}: type not known")
            self.graph.topic_types[topic] = self.graph.msg_type(type_)
        self.graph.node(BRIDGE_NODE).subs.add(topic)
        sub = client.subs.setdefault(topic, Subscription())
        sub.ids[msg.get("id")] = (max(throttle, 0), max(qlen, 0))
        self.subscribers.setdefault(topic, {})[client] = sub
        if topic in self.latched:
            client.send(self.latched[topic])

    def _unsubscribe(self, client: Client, msg: dict) -> None:
        topic = _name(msg, "topic")
        sub = client.subs.get(topic)
        if sub is None:
            return
        sub.ids.pop(msg.get("id"), None)
        if not sub.ids or "id" not in msg:
            self._remove_sub(client, topic)

    def _remove_sub(self, client: Client, topic: str) -> None:
        client.subs.pop(topic, None)
        subs = self.subscribers.get(topic, {})
        subs.pop(client, None)
        if not subs:
            self.subscribers.pop(topic, None)
            self.graph.node(BRIDGE_NODE).subs.discard(topic)

    def _call_service(self, client: Client, msg: dict) -> None:
        service = _name(msg, "service")
        call_id = msg.get("id")
        if "#" in service and call_id is None:
            service, call_id = service.split("#", 1)
        args = msg.get("args", [])
        if args == []:
            args = {}
        if not isinstance(args, (dict, list)):
            raise BadMessage(
                f"call_service: Expected field args to be one of (list, dict). Invalid value: {args!r}"
            )
        reply = {"op": "service_response", "service": service}
        if call_id is not None:
            reply["id"] = call_id
        handler = self.graph.service_handlers.get(service)
        try:
            if handler is None:
                raise ServiceError(f"Service {service} does not exist")
            if isinstance(args, list):
                raise ServiceError(f"{service}: positional args are not supported by this simulator")
            values = handler(args)
        except ServiceError as exc:
            client.send(json.dumps({**reply, "values": str(exc), "result": False}))
            return
        if isinstance(values, asyncio.Future):
            task = asyncio.ensure_future(self._finish_call(client, reply, values))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            return
        client.send(json.dumps({**reply, "values": values, "result": True}))

    async def _finish_call(self, client: Client, reply: dict, pending: asyncio.Future) -> None:
        """Relay the answer of a client-provided service (or its failure) to the caller."""
        try:
            async with asyncio.timeout(SERVICE_TIMEOUT):
                values = await pending
            client.send(json.dumps({**reply, "values": values, "result": True}))
        except (ServiceError, TimeoutError, asyncio.CancelledError) as exc:
            text = str(exc) or f"Service {reply['service']} did not answer"
            client.send(json.dumps({**reply, "values": text, "result": False}))

    def _advertise_service(self, client: Client, msg: dict) -> None:
        service, type_ = _name(msg, "service"), _field(msg, "type", str)
        counter = iter(range(1, 1 << 62))

        def forward(args: dict) -> asyncio.Future:
            call_id = f"service_request:{service}:{next(counter)}"
            future = asyncio.get_running_loop().create_future()
            client.pending[call_id] = future
            client.send(json.dumps({"op": "call_service", "id": call_id, "service": service, "args": args}))
            return future

        client.provided.add(service)
        self.graph.add_service(
            BRIDGE_NODE, service, self.graph.msg_type(type_).replace("/msg/", "/srv/"), forward
        )

    def _unadvertise_service(self, client: Client, msg: dict) -> None:
        service = _name(msg, "service")
        if service in client.provided:
            self._remove_service(client, service)

    def _remove_service(self, client: Client, service: str) -> None:
        client.provided.discard(service)
        self.graph.node(BRIDGE_NODE).services.discard(service)
        self.graph.service_types.pop(service, None)
        self.graph.service_handlers.pop(service, None)

    def _service_response(self, client: Client, msg: dict) -> None:
        _field(msg, "service", str)
        ok = _field(msg, "result", bool)
        future = client.pending.pop(str(msg.get("id")), None)
        if future is None or future.done():
            raise BadMessage(f"service_response: no pending request with id {msg.get('id')}")
        values = msg.get("values", {})
        if ok:
            future.set_result(values if isinstance(values, dict) else {})
        else:
            future.set_exception(ServiceError(str(values)))

    def _fragment(self, client: Client, msg: dict) -> None:
        """Reassemble a fragmented message and dispatch it once all parts arrived."""
        frag_id = str(_field(msg, "id", (str, int)))
        data, num, total = (
            _field(msg, "data", str),
            _field(msg, "num", int),
            _field(msg, "total", (int, float)),
        )
        if not 0 <= num < total <= MAX_FRAGMENTS:
            raise BadMessage(f"fragment: bad num/total {num}/{total}")
        parts = client.fragments.setdefault(frag_id, {})
        parts[num] = data
        if len(parts) >= int(total):
            del client.fragments[frag_id]
            self.dispatch(client, "".join(parts[i] for i in sorted(parts)))

    def _send_action_goal(self, client: Client, msg: dict) -> None:
        action = _name(msg, "action")
        _field(msg, "action_type", str)
        goal_id = str(msg.get("id") or f"send_action_goal:{action}:{len(self.goals)}")
        args = msg.get("args", {})
        if not isinstance(args, dict):
            raise BadMessage(f"send_action_goal: Expected field args to be a dict. Invalid value: {args!r}")
        goal = ActionGoal(self, client, action, goal_id, bool(msg.get("feedback", False)))
        if action not in self.actions:
            goal.finish(f"Action {action} does not exist", status=0, ok=False)
            return
        self.goals[goal_id] = goal
        self.actions[action][1](goal, args)

    def _cancel_action_goal(self, client: Client, msg: dict) -> None:
        _field(msg, "action", str)
        goal = self.goals.get(str(msg.get("id")))
        if goal is not None and goal.client is client:
            goal.cancel()


class ActionGoal:
    """One ROS 2 action goal sent over rosbridge: feedback, result and cancellation."""

    def __init__(
        self, server: RosbridgeServer, client: Client, action: str, goal_id: str, feedback: bool
    ) -> None:
        self.server, self.client, self.action, self.id = server, client, action, goal_id
        self.want_feedback = feedback
        self.cancelled = False
        self.on_cancel: Callable[[], None] | None = None

    def feedback(self, values: dict) -> None:
        if self.want_feedback:
            self.client.send(
                json.dumps({"op": "action_feedback", "action": self.action, "values": values, "id": self.id})
            )

    def finish(self, values, status: int, ok: bool = True) -> None:
        """Send action_result (status per action_msgs/GoalStatus: 4 succeeded, 5 canceled, 6 aborted)."""
        self.server.goals.pop(self.id, None)
        self.client.send(
            json.dumps(
                {
                    "op": "action_result",
                    "action": self.action,
                    "values": values,
                    "status": status,
                    "result": ok,
                    "id": self.id,
                }
            )
        )

    def cancel(self) -> None:
        self.cancelled = True
        if self.on_cancel is not None:
            self.on_cancel()


def _field(msg: dict, name: str, type_: type, required: bool = True):
    """Return msg[name] checked against type_, as rosbridge's basic_type_check does."""
    if name not in msg or msg[name] is None:
        if required:
            raise BadMessage(f"{msg.get('op')}: Expected a {name} field but none was found.")
        return None
    value = msg[name]
    types = type_ if isinstance(type_, tuple) else (type_,)
    if not isinstance(value, types) or (bool not in types and isinstance(value, bool)):
        names = ", ".join(t.__name__ for t in types)
        raise BadMessage(
            f"{msg.get('op')}: Expected field {name} to be one of ({names}). Invalid value: {value!r}"[:300]
        )
    return value


def _name(msg: dict, key: str) -> str:
    """Return a graph name resolved as the rosbridge node (namespace /) resolves it: `a/b` is `/a/b`."""
    name = _field(msg, key, str)
    return name if name.startswith("/") else "/" + name


def _norm(type_: str) -> str:
    return type_.replace("/msg/", "/").replace("/srv/", "/")
