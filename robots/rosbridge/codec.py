"""rosbridge v2 messages as roslibpy builds them, and decoding of what a server sends.

Builders return plain dicts with the same keys, defaults and id formats as roslibpy 2.1
(`core.py`: `call_service:<service>:<n>`, `subscribe:<topic>:<n>`, `advertise:<topic>:<n>`,
`publish:<topic>:<n>`, `send_action_goal:<action>:<n>`; one counter per connection).
tests/robots/test_wire_format.py compares them with roslibpy's own.
"""

from __future__ import annotations

import itertools
import json
import math

from fleetcore import jsontext
from robots.limits import FRAME_SETTING, megabytes
from robots.rosbridge.errors import BadFrame, FrameTooLarge, NotRosbridgeError


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


_COMPACT = json.JSONEncoder(separators=(",", ":"))  # json.dumps with separators builds an encoder per call


def encode(message: dict) -> str:
    """Encode one frame as compact JSON text."""
    return _COMPACT.encode(message)


def decode(raw: str | bytes) -> dict:
    """Decode one frame; anything but a JSON object with a string `op` is NotRosbridgeError."""
    try:
        if isinstance(raw, bytes):
            raw = raw.decode("utf-8")
        message = jsontext.loads(raw)  # every process holding a link reads every robot's odometry
    except (UnicodeDecodeError, ValueError):
        raise NotRosbridgeError(f"answered a frame that is not JSON: {preview(raw)}") from None
    except RecursionError:
        raise NotRosbridgeError(f"answered JSON nested too deeply: {preview(raw)}") from None
    if not isinstance(message, dict) or not isinstance(message.get("op"), str):
        raise NotRosbridgeError(f"answered JSON without an 'op': {preview(raw)}")
    return message


def preview(value, limit: int = 60) -> str:
    """A short quotation of something a server sent, for one-line errors and logs (never the whole of it)."""
    text = value if isinstance(value, str) else repr(value)
    return repr(text[:limit] + ("..." if len(text) > limit else ""))


def clip(value, limit: int = 300) -> str:
    """A server's own error text for an exception message, cut to one bounded line."""
    text = " ".join((value if isinstance(value, str) else repr(value))[: limit + 1].split())
    return text[:limit] + ("..." if len(text) > limit else "")


# ----- what the fields of incoming ops must be -----
def _text(value) -> bool:
    return isinstance(value, str)


def _object(value) -> bool:
    return isinstance(value, dict)


def _flag(value) -> bool:
    return isinstance(value, bool)


def _whole(value) -> bool:
    """An integer (3.0 counts: JSON has one number type)."""
    if isinstance(value, bool):
        return False
    return isinstance(value, int) or (isinstance(value, float) and value.is_integer())


def _count(value) -> bool:
    """A finite number: rosbridge computes a fragment's `total` as (len - 1) / size + 1, a float (§2.2)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _key(value) -> bool:
    """A fragment id: the message's own id (text), or rosbridge's counter (an integer)."""
    return _text(value) or (isinstance(value, int) and not isinstance(value, bool))


# op -> field -> (check, required). Ops not listed (status, set_level, ...) are ignored by the client.
FIELDS = {
    "publish": {"topic": (_text, True), "msg": (_object, True)},
    "service_response": {"id": (_text, True), "result": (_flag, False)},
    "action_feedback": {"id": (_text, True), "values": (_object, False)},
    "action_result": {"id": (_text, True), "result": (_flag, False), "status": (_whole, False)},
    "fragment": {"id": (_key, True), "data": (_text, True), "num": (_whole, True), "total": (_count, True)},
}


def check(message: dict) -> dict:
    """Check the fields the client reads from one incoming op; BadFrame names the first wrong one."""
    for name, (valid, required) in FIELDS.get(message["op"], {}).items():
        if name not in message:
            if required:
                raise BadFrame(f"{message['op']} without {name!r}")
        elif not valid(message[name]):
            raise BadFrame(f"{message['op']} with {name!r} = {preview(message[name])}")
    return message


MAX_FRAGMENT_PARTS = 100_000


class Fragments:
    """Reassemble `fragment` ops within a byte budget (the frame limit: one message, in parts, is still one).

    Parts of unfinished messages count against the budget until they complete; a part that would exceed it,
    a `num` outside 0..total-1 or a `total` that changes drops that message's parts (BadFrame).
    """

    def __init__(self, max_bytes: int, max_parts: int = MAX_FRAGMENT_PARTS) -> None:
        self.max_bytes, self.max_parts = max_bytes, max_parts
        self._parts: dict[str, tuple[int, dict[int, str]]] = {}
        self._bytes = 0

    def add(self, message: dict) -> dict | None:
        """Store one checked fragment; return the whole decoded message once every part arrived."""
        key, data = str(message["id"]), message["data"]
        num, total = int(message["num"]), int(message["total"])
        known_total, parts = self._parts.get(key, (total, {}))
        if not 0 < total <= self.max_parts or not 0 <= num < total or total != known_total:
            self._drop(key)
            raise BadFrame(f"fragment {num} of {total} of {preview(key)} does not fit its message")
        self._bytes += len(data) - len(parts.get(num, ""))
        parts[num] = data
        self._parts[key] = (total, parts)
        if self._bytes > self.max_bytes:
            self._drop(key)
            raise FrameTooLarge(
                f"fragments of {preview(key)} add up to more than the {megabytes(self.max_bytes)} limit "
                f"({FRAME_SETTING})"
            )
        if len(parts) < total:
            return None
        self._drop(key)
        whole = decode("".join(parts[i] for i in range(total)))
        if whole["op"] == "fragment":
            raise BadFrame(f"fragment {preview(key)} holds another fragment")
        return whole

    def _drop(self, key: str) -> None:
        _total, parts = self._parts.pop(key, (0, {}))
        self._bytes -= sum(len(part) for part in parts.values())
