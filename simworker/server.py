"""A rosbridge v2 WebSocket server for one simulated endpoint (asyncio + websockets).

It follows rosbridge_suite (the `ros2` and `ros1` branches of rosbridge_library) rather than the protocol text:
published messages, service requests and client services' responses are completed with their type's defaults
and dropped with the real server's log line when they do not fit (`simworker/messages.py`); a subscription
with a type other than the topic's streams nothing; `compression` (png, cbor) and `fragment_size` shape what
goes out. The server never sends `status`; bad input is logged (`[Client <uuid>] [id: <id>] <op>: <reason>`,
at error level, as rosbridge logs it) and dropped; only a failed service call answers (`result: false` with
the error text). Every client has a bounded send queue drained by its own writer task, so a client that never
reads loses messages (and is cut off) without slowing anyone else (`simworker/connection.py`).

Where it still differs from the real server: docs/simulator.md.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Callable

from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from fleetcore import jsontext
from simworker import outgoing, rosapi
from simworker.connection import Client, Deferred, Subscription
from simworker.graph import Graph, ServiceError
from simworker.messages import ConversionError, registry

log = logging.getLogger("simworker.server")

MAX_MESSAGE_SIZE = 10_000_000  # rosbridge's max_message_size; bigger frames close the connection (1009)
SERVICE_TIMEOUT = 10.0  # a client-provided service that does not answer fails after this
MAX_FRAGMENTS = 10_000
# A client's messages already read are handled for up to this long before the loop turns (the physics, the
# other clients). rosbridge handles a burst without a turn per message; on a loaded endpoint a turn per message
# put every message of a burst behind everything else the loop had to do (300 publishes: 299 turns).
BURST_S = 0.002
BRIDGE_NODE = "/rosbridge_websocket"


class BadMessage(Exception):
    """An incoming message the server drops (logged, never answered, as rosbridge does)."""


class TypeConflict(BadMessage):
    """rosbridge's TypeConflictException: a topic used with a type other than its own."""

    def __init__(self, topic: str, new: str, established: str) -> None:
        super().__init__(
            f"Tried to register topic {topic} with type {new} but it is already established with type"
            f" {established}"
        )


class RosbridgeServer:
    """Serve one endpoint's graph over rosbridge v2."""

    def __init__(self, key: str, graph: Graph, port: int) -> None:
        self.key = key
        self.graph = graph
        self.types = registry(graph.ros_version)
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

    def wants(self, topic: str) -> bool:
        """Whether a message on topic now would reach anyone: a subscriber past its throttle, or a latch
        (periodic publishers build nothing for throttled subscribers, as rosbridge serialises nothing for them)."""
        subs = self.subscribers.get(topic)
        return topic in self.graph.latched_topics or (bool(subs) and any(s.due() for s in subs.values()))

    def publish(self, topic: str, msg: dict) -> None:
        """Publish a message dict on topic (latched topics keep it for later subscribers)."""
        if topic in self.subscribers or topic in self.graph.latched_topics:
            self.publish_text(topic, json.dumps(msg, separators=(",", ":")))

    def publish_text(self, topic: str, msg_json: str | Deferred) -> None:
        """Publish an already-encoded message body on topic; a Deferred one is written only for a client that
        sends it (not for one that holds it until a newer replaces it)."""
        subscribers = self.subscribers.get(topic, {})
        latched = topic in self.graph.latched_topics
        if isinstance(msg_json, Deferred):
            if latched or any(sub.compression != "none" for sub in subscribers.values()):
                msg_json = msg_json()
            else:
                body = msg_json
                frame = Deferred(lambda: outgoing.publish_op(topic, body()))
                for client, sub in subscribers.items():
                    client.send(frame, sub)
                return
        text = outgoing.publish_op(topic, msg_json)
        if latched:
            self.latched[topic] = text
        encoded: dict[str, str | bytes] = {"none": text}
        for client, sub in subscribers.items():
            if (how := sub.compression) not in encoded:
                encoded[how] = outgoing.compress(how, topic, msg_json, self.types, self._definition(topic))
            client.send(encoded[how], sub)

    def _definition(self, topic: str):
        """The message definition of a topic's type, None where the simulator does not know it."""
        return self.types.message(self.graph.topic_types.get(topic, ""))

    def add_action(self, name: str, type_: str, handler: Callable) -> None:
        """Serve a ROS 2 action through send_action_goal: handler(goal) is called with an ActionGoal."""
        self.actions[name] = (type_, handler)

    # ----- connections -----
    async def _handle(self, ws: ServerConnection) -> None:
        client = Client(ws, topics=len(self.graph.topic_handlers))
        self.clients.add(client)
        self._client_topics()
        writer = asyncio.create_task(client.writer())
        try:
            turn_ends = time.monotonic() + BURST_S
            async for raw in ws:
                self.dispatch(client, raw)
                if time.monotonic() >= turn_ends:  # let the physics and other clients run
                    await asyncio.sleep(0)
                    turn_ends = time.monotonic() + BURST_S
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
        """Decode one frame and run its op; anything wrong is logged (as rosbridge's protocol logs it)."""
        try:
            msg = jsontext.loads(raw.decode("utf-8") if isinstance(raw, bytes) else raw)
        except (ValueError, UnicodeDecodeError) as exc:  # rosbridge drops undecodable input silently
            log.debug("%s: undecodable message dropped: %s", self.key, exc)
            return
        if not isinstance(msg, dict):
            return
        mid = msg.get("id")
        op = msg.get("op")
        if "op" not in msg:
            allowed = list(self.ops)
            return self._log(client, f"Received a message without an op.  All messages require 'op' field"
                             f" with value one of: {allowed}.  Original message was: {raw}", mid)  # fmt: skip
        handler = self.ops.get(op) if isinstance(op, str) else None
        if handler is None:
            return self._log(client, f"Unknown operation: {op}.  Allowed operations: {list(self.ops)}", mid)
        if "fragment_size" in msg:  # rosbridge keeps it for everything it sends this client from now on
            client.fragment_size = msg["fragment_size"] if isinstance(msg["fragment_size"], int) else None
        if op == "publish" and not client.allow():
            client.dropped += 1  # a publish flood: the excess is dropped
            return
        try:
            handler(client, msg)
        except (BadMessage, ConversionError, ServiceError) as exc:
            self._log(client, f"{op}: {exc}", mid)
        except Exception:  # a bug in a handler must not take the endpoint down
            log.exception("%s: error handling message", self.key)

    def _log(self, client: Client, text: str, mid=None) -> None:
        """Log at error level as rosbridge's Protocol.log does: `[Client <id>] [id: <mid>] <text>`."""
        prefix = f"[Client {client.id}]" if mid is None else f"[Client {client.id}] [id: {mid}]"
        log.error("%s %s", prefix, text)

    # ----- ops -----
    def _advertise(self, client: Client, msg: dict) -> None:
        topic, type_ = _name(msg, "topic"), _field(msg, "type", str)
        known = self.graph.topic_types.get(topic)
        if known and _norm(known) != _norm(type_):
            raise TypeConflict(topic, self.types.type_name(type_), known)
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
        """Publish a client's message completed with its type's defaults; one that does not fit is dropped."""
        topic = _name(msg, "topic")
        body = msg.get("msg", {})
        if topic not in self.graph.topic_types:
            raise BadMessage(f"Cannot infer topic type for topic {topic} as it is not yet advertised")
        definition = self._definition(topic)
        if definition is not None:
            body = self.types.populate(definition, body)
        elif not isinstance(body, dict):
            raise BadMessage(f"Expected a JSON object for type {self.graph.topic_types[topic]}")
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
        _field(msg, "fragment_size", int, required=False)
        compression = _field(msg, "compression", str, required=False) or "none"
        known = self.graph.topic_types.get(topic)
        if known is None:
            if not type_:
                raise BadMessage(f"Cannot infer topic type for topic {topic} as it is not yet advertised")
            self.graph.topic_types[topic] = self.graph.msg_type(type_)
        elif type_ and _norm(type_) != _norm(known):  # the real server subscribes nothing: nothing streams
            raise TypeConflict(topic, self.types.type_name(type_), known)
        self.graph.node(BRIDGE_NODE).subs.add(topic)
        sub = client.subs.setdefault(topic, Subscription())
        sub.add(msg.get("id"), throttle, qlen, compression)
        self.subscribers.setdefault(topic, {})[client] = sub
        if topic in self.latched:
            client.send(self.latched[topic])

    def _unsubscribe(self, client: Client, msg: dict) -> None:
        topic = _name(msg, "topic")
        sub = client.subs.get(topic)
        if sub is None:
            return
        sub.remove(msg.get("id"))
        if not sub.ids or "id" not in msg:
            self._remove_sub(client, topic)

    def _remove_sub(self, client: Client, topic: str) -> None:
        if (sub := client.subs.pop(topic, None)) is not None:
            sub.end()
        subs = self.subscribers.get(topic, {})
        subs.pop(client, None)
        if not subs:
            self.subscribers.pop(topic, None)
            self.graph.node(BRIDGE_NODE).subs.discard(topic)

    def _call_service(self, client: Client, msg: dict) -> None:
        """Call a service with the request completed from args (a dict, or a list: positional) as
        rosbridge's call_service does; a request that does not fit fails the call, logged and answered."""
        service = _name(msg, "service")
        _field(msg, "fragment_size", (int, type(None)), required=False)
        _field(msg, "compression", str, required=False)
        call_id = msg.get("id")
        if "#" in service and call_id is None:
            service, call_id = service.split("#", 1)
        reply = {"op": "service_response", "service": service}
        if call_id is not None:
            reply["id"] = call_id
        try:
            values = self._serve(service, msg.get("args", []))
        except (ServiceError, ConversionError) as exc:
            self._call_failed(client, reply, exc)
            return
        if isinstance(values, asyncio.Future):
            task = asyncio.ensure_future(self._finish_call(client, reply, values))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            return
        client.send(json.dumps({**reply, "values": values, "result": True}))

    def _serve(self, service: str, args):
        """The handler's answer to args read as the service type's request (rosbridge's
        args_to_service_request_instance); raise ServiceError or ConversionError where the call fails."""
        handler = self.graph.service_handlers.get(service)
        if handler is None:
            raise ServiceError(f"Service {service} does not exist")
        parts = self.types.service(self.graph.service_types.get(service, ""))
        if parts is None:  # a type the simulator does not know: args passed on as sent
            return handler(args if isinstance(args, dict) else {})
        request, response = parts
        if isinstance(args, list):
            args = dict(zip((f.name for f in request.fields), args, strict=False))
        values = handler(self.types.populate(request, args if isinstance(args, dict) else {}))
        if isinstance(values, asyncio.Future):
            return values
        try:
            return self.types.populate(response, values)
        except ConversionError as exc:  # the simulator's own answer does not fit: its bug, said loudly
            log.warning("%s: %s answered a %s that does not fit: %s", self.key, service, response.name, exc)
            return values

    def _call_failed(self, client: Client, reply: dict, exc: Exception) -> None:
        """rosbridge's CallService._failure: log the exception, answer result false with its text."""
        kind = getattr(exc, "kind", None) or (
            "InvalidServiceException" if str(exc).endswith("does not exist") else type(exc).__name__
        )
        self._log(client, f"call_service {kind}: {exc}", reply.get("id"))
        client.send(json.dumps({**reply, "values": str(exc), "result": False}))

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
        """A client's answer to a call forwarded to its service. As rosbridge's ServiceResponse, `result` must
        be a bool but is not read: the values, completed as the response type, are the answer."""
        service = _name(msg, "service")
        _field(msg, "id", str, required=False)
        _field(msg, "values", dict, required=False)
        _field(msg, "result", bool)
        if service not in client.provided:
            raise BadMessage(f"Service {service} has not been advertised via rosbridge.")
        for key in ("id", "values"):
            if key not in msg:
                raise BadMessage(repr(key))  # rosbridge's KeyError, logged as such
        parts = self.types.service(self.graph.service_types.get(service, ""))
        values = self.types.populate(parts[1], msg["values"]) if parts else msg["values"]
        future = client.pending.pop(msg["id"], None)
        if future is not None and not future.done():
            future.set_result(values)

    def _fragment(self, client: Client, msg: dict) -> None:
        """Reassemble a fragmented message and dispatch it once all parts arrived."""
        frag_id = str(_field(msg, "id", (str, int)))
        data, num, total = (
            _field(msg, "data", str),
            _field(msg, "num", int),
            _field(msg, "total", (int, float)),
        )
        if not 0 <= num < total <= MAX_FRAGMENTS:
            raise BadMessage(f"bad num/total {num}/{total}")
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
            raise BadMessage(f"Expected field args to be a dict. Invalid value: {args!r}")
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


def _field(msg: dict, name: str, type_: type | tuple, required: bool = True):
    """Return msg[name] checked against type_ as rosbridge's Capability.basic_type_check checks it."""
    if name not in msg:
        if required:
            raise BadMessage(f"Expected a {name} field but none was found.")
        return None
    value = msg[name]
    types = type_ if isinstance(type_, tuple) else (type_,)
    if not isinstance(value, types):
        raise BadMessage(f"Expected field {name} to be one of {types}. Invalid value: {value}")
    return value


def _name(msg: dict, key: str) -> str:
    """Return a graph name resolved as the rosbridge node (namespace /) resolves it: `a/b` is `/a/b`."""
    name = _field(msg, key, str)
    return name if name.startswith("/") else "/" + name


def _norm(type_: str) -> str:
    return type_.replace("/msg/", "/").replace("/srv/", "/")
