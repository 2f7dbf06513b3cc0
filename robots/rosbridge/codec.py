"""rosbridge v2 messages as roslibpy builds them, and decoding of what a server sends.

Builders return plain dicts with the same keys, defaults and id formats as roslibpy 2.1
(`core.py`: `call_service:<service>:<n>`, `subscribe:<topic>:<n>`, `advertise:<topic>:<n>`,
`publish:<topic>:<n>`, `send_action_goal:<action>:<n>`; one counter per connection).
tests/robots/test_wire_format.py compares them with roslibpy's own.
"""

from __future__ import annotations

import itertools
import json

from robots.rosbridge.errors import NotRosbridgeError


class Ids:
    """The per-connection id counter, starting at 1 like roslibpy's `Ros.id_counter`."""

    def __init__(self) -> None:
        self._next = itertools.count(1)

    def make(self, op: str, name: str) -> str:
        return f"{op}:{name}:{next(self._next)}"


def call_service(ids: Ids, service: str, args: dict | None = None) -> dict:
    return {
        "op": "call_service",
        "id": ids.make("call_service", service),
        "service": service,
        "args": dict(args or {}),
    }


def subscribe(
    ids: Ids, topic: str, type_: str, throttle_rate: int = 0, queue_length: int = 0, compression: str = "none"
) -> dict:
    return {
        "op": "subscribe",
        "id": ids.make("subscribe", topic),
        "type": type_,
        "topic": topic,
        "compression": compression,
        "throttle_rate": throttle_rate,
        "queue_length": queue_length,
    }


def unsubscribe(sub_id: str, topic: str) -> dict:
    return {"op": "unsubscribe", "id": sub_id, "topic": topic}


def advertise(ids: Ids, topic: str, type_: str, latch: bool = False, queue_size: int = 100) -> dict:
    return {
        "op": "advertise",
        "id": ids.make("advertise", topic),
        "type": type_,
        "topic": topic,
        "latch": latch,
        "queue_size": queue_size,
    }


def unadvertise(adv_id: str, topic: str) -> dict:
    return {"op": "unadvertise", "id": adv_id, "topic": topic}


def publish(ids: Ids, topic: str, msg: dict, latch: bool = False) -> dict:
    return {
        "op": "publish",
        "id": ids.make("publish", topic),
        "topic": topic,
        "msg": dict(msg),
        "latch": latch,
    }


def send_action_goal(ids: Ids, action: str, action_type: str, goal: dict, feedback: bool = True) -> dict:
    return {
        "op": "send_action_goal",
        "id": ids.make("send_action_goal", action),
        "action": action,
        "action_type": action_type,
        "args": dict(goal),
        "feedback": feedback,
    }


def cancel_action_goal(goal_id: str, action: str) -> dict:
    return {"op": "cancel_action_goal", "id": goal_id, "action": action}


def encode(message: dict) -> str:
    """Encode one frame as compact JSON text."""
    return json.dumps(message, separators=(",", ":"))


def decode(raw: str | bytes) -> dict:
    """Decode one frame; anything but a JSON object with a string `op` is NotRosbridgeError."""
    try:
        if isinstance(raw, bytes):
            raw = raw.decode("utf-8")
        message = json.loads(raw)
    except (UnicodeDecodeError, ValueError):
        raise NotRosbridgeError(f"answered a frame that is not JSON: {_preview(raw)}") from None
    if not isinstance(message, dict) or not isinstance(message.get("op"), str):
        raise NotRosbridgeError(f"answered JSON without an 'op': {_preview(raw)}")
    return message


def _preview(raw) -> str:
    text = raw if isinstance(raw, str) else repr(raw)
    return repr(text[:60] + ("..." if len(text) > 60 else ""))


class Fragments:
    """Reassemble `fragment` ops (rosbridge's `total` may arrive as a float, protocol §2.2)."""

    def __init__(self) -> None:
        self._parts: dict[str, dict[int, str]] = {}

    def add(self, message: dict) -> dict | None:
        """Store one fragment; return the whole decoded message once every part arrived."""
        key = str(message.get("id"))
        total = int(message.get("total", 0))
        parts = self._parts.setdefault(key, {})
        parts[int(message.get("num", 0))] = str(message.get("data", ""))
        if len(parts) < total:
            return None
        del self._parts[key]
        return decode("".join(parts[i] for i in sorted(parts)))
