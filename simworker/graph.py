"""One endpoint's ROS graph: nodes, topics, services, params, as a ROS master would report them."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field


class ServiceError(Exception):
    """A service call that fails; the text goes back as `values` with `result: false`."""


@dataclass
class NodeInfo:
    pubs: set[str] = field(default_factory=set)
    subs: set[str] = field(default_factory=set)
    services: set[str] = field(default_factory=set)


@dataclass
class Graph:
    """Nodes, topic and service types, service handlers, params and internal topic handlers."""

    ros_version: int
    clock: Callable[[], float]
    nodes: dict[str, NodeInfo] = field(default_factory=dict)
    topic_types: dict[str, str] = field(default_factory=dict)
    service_types: dict[str, str] = field(default_factory=dict)
    service_handlers: dict[str, Callable[[dict], dict]] = field(default_factory=dict)
    params: dict[str, object] = field(default_factory=dict)
    topic_handlers: dict[str, list[Callable[[dict], None]]] = field(default_factory=dict)
    latched_topics: set[str] = field(default_factory=set)

    def node(self, name: str) -> NodeInfo:
        """Return the node, creating it if needed."""
        return self.nodes.setdefault(name, NodeInfo())

    def add_publisher(self, node: str, topic: str, type_: str) -> None:
        self.node(node).pubs.add(topic)
        self.topic_types.setdefault(topic, type_)

    def add_subscriber(self, node: str, topic: str, type_: str) -> None:
        self.node(node).subs.add(topic)
        self.topic_types.setdefault(topic, type_)

    def add_service(
        self, node: str, name: str, type_: str, handler: Callable[[dict], dict] | None = None
    ) -> None:
        """Register a service; without a handler it answers with the type's default response."""
        self.node(node).services.add(name)
        self.service_types[name] = type_
        self.service_handlers[name] = handler or default_handler(type_)

    def on_topic(self, topic: str, handler: Callable[[dict], None]) -> None:
        """Call handler(msg) for every message published on topic by a client."""
        self.topic_handlers.setdefault(topic, []).append(handler)

    def publishers(self, topic: str) -> list[str]:
        return sorted(n for n, info in self.nodes.items() if topic in info.pubs)

    def subscribers(self, topic: str) -> list[str]:
        return sorted(n for n, info in self.nodes.items() if topic in info.subs)

    def topics(self) -> list[str]:
        """Return topics with at least one publisher or subscriber, in registration order."""
        live = set()
        for info in self.nodes.values():
            live |= info.pubs | info.subs
        return [t for t in self.topic_types if t in live]

    def services(self) -> list[str]:
        return [s for s in self.service_types if any(s in i.services for i in self.nodes.values())]

    def stamp(self, t: float | None = None) -> dict:
        """Return a time as this ROS version encodes it."""
        t = self.clock() if t is None else t
        sec = int(t)
        nsec = int((t - sec) * 1e9)
        if self.ros_version == 1:
            return {"secs": sec, "nsecs": nsec}
        return {"sec": sec, "nanosec": nsec}

    def header(self, frame_id: str, t: float | None = None) -> dict:
        header = {"stamp": self.stamp(t), "frame_id": frame_id}
        return {"seq": 0, **header} if self.ros_version == 1 else header

    def msg_type(self, ros1_name: str) -> str:
        """Spell a ROS 1 `pkg/Type` the way this graph reports it."""
        if self.ros_version == 1 or "/msg/" in ros1_name or "/srv/" in ros1_name:
            return ros1_name
        pkg, name = ros1_name.split("/", 1)
        return f"{pkg}/msg/{name}"


DEFAULT_RESPONSES = {
    "Trigger": lambda: {"success": True, "message": ""},
    "SetBool": lambda: {"success": True, "message": ""},
    "GetLoggers": lambda: {"loggers": [{"name": "ros", "level": "info"}]},
}


def default_handler(type_: str) -> Callable[[dict], dict]:
    """Return a handler answering with the default response of a service type."""
    make = DEFAULT_RESPONSES.get(type_.rsplit("/", 1)[-1], dict)
    return lambda _args: make()


def decode_param(text: str):
    """Decode a JSON-encoded param value as rosapi does; plain strings pass through."""
    try:
        return json.loads(text)
    except (TypeError, ValueError):
        return text
