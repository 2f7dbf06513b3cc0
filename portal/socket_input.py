"""What a page's WebSocket accepts from a browser: one JSON object per text frame, at a bounded rate.

Everything else is answered in words on the socket (``BadFrame``), never with a traceback or a dropped socket.
No Django, no database: the consumer (portal.consumers) calls these before any work.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field

MAX_FRAME_CHARS = 64 * 1024  # a command is a few hundred characters; a list of 1,000 robot ids under 10 KB
MAX_DEPTH = 8  # {"command": ..., "robots": [...]} is two levels deep
MAX_ID = 2**63 - 1  # the largest primary key either database stores
MAX_ROBOTS = 10_000


class BadFrame(Exception):
    """A frame the portal does not accept; the message names the field and says what is expected."""


def decode(text_data: str | None, bytes_data: bytes | None) -> dict:
    """The command in one frame, or BadFrame saying why not."""
    if text_data is None:
        raise BadFrame("frame: binary frames are not accepted; send a JSON object as text")
    if len(text_data) > MAX_FRAME_CHARS:
        raise BadFrame(f"frame: longer than {MAX_FRAME_CHARS} characters")
    try:
        content = json.loads(text_data)
    except (ValueError, RecursionError):
        raise BadFrame('frame: not valid JSON; send e.g. {"command": "stop", "robots": "all"}') from None
    if _depth(content) > MAX_DEPTH:
        raise BadFrame(f"frame: nested deeper than {MAX_DEPTH} levels")
    if not isinstance(content, dict):
        raise BadFrame('frame: a JSON object is expected, e.g. {"command": "stop", "robots": "all"}')
    return content


def _depth(value) -> int:
    """How deeply lists and objects nest (iteratively: a hostile frame cannot exhaust the stack)."""
    if isinstance(value, dict):  # a held button's command, every 0.2 s: one object of plain values
        for child in value.values():
            if isinstance(child, (dict, list)):
                break
        else:
            return 1
    deepest, todo = 0, [(value, 1)]
    while todo:
        item, depth = todo.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, depth)
            if deepest > MAX_DEPTH:
                return deepest
            todo.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def robot_id(value) -> int:
    """One robot id: a whole number the database can hold."""
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_ID:
        raise BadFrame("robot: give one robot id (a whole number)")
    return value


def robot_ids(value) -> list[int] | str:
    """ "all", or a list of robot ids."""
    if value == "all":
        return value
    if not isinstance(value, list) or len(value) > MAX_ROBOTS:
        raise BadFrame(f'robots: give "all" or a list of at most {MAX_ROBOTS} robot ids')
    try:
        return [robot_id(pk) for pk in value]
    except BadFrame:
        raise BadFrame('robots: give "all" or a list of robot ids (whole numbers)') from None


# --- rate ----------------------------------------------------------------------------------------------------


@dataclass
class Bucket:
    tokens: float
    at: float
    warned_at: float = -1e9


@dataclass
class RateLimiter:
    """Token buckets per key, and one for the whole socket.

    Keys are (command, robot) for teleop and (command,) otherwise, so a stuck teleop key floods only its own
    bucket: a stop from the same page still gets through, and so do the other robots' held buttons (a fleet page
    holds hundreds at 5 Hz each). Over budget, a message is dropped and the person told once a second per key.
    """

    rate: float = 20.0  # per key, per second: a held button sends 5
    burst: float = 20.0
    socket_rate: float = 5000.0  # the whole socket
    max_keys: int = 4096
    clock: Callable[[], float] = time.monotonic
    buckets: dict = field(default_factory=dict)

    def __post_init__(self):
        self.whole = Bucket(self.socket_rate, self.clock())

    def allow(self, key: tuple) -> bool:
        """Spend one token of the key's bucket and the socket's; False when either is empty."""
        now = self.clock()
        if key not in self.buckets and len(self.buckets) >= self.max_keys:
            key = ("too many keys",)
        bucket = self.buckets.setdefault(key, Bucket(self.burst, now))
        _refill(bucket, now, self.rate, self.burst)
        _refill(self.whole, now, self.socket_rate, self.socket_rate)
        if bucket.tokens < 1 or self.whole.tokens < 1:
            return False
        bucket.tokens -= 1
        self.whole.tokens -= 1
        return True

    def warn(self, key: tuple) -> bool:
        """Whether to tell the person about a dropped message now (once a second per key)."""
        bucket = self.buckets.get(key) or self.buckets.get(("too many keys",))
        now = self.clock()
        if bucket is None or now - bucket.warned_at < 1.0:
            return False
        bucket.warned_at = now
        return True


def _refill(bucket: Bucket, now: float, rate: float, burst: float) -> None:
    bucket.tokens = min(burst, bucket.tokens + (now - bucket.at) * rate)
    bucket.at = now


def rate_key(content: dict) -> tuple:
    """The bucket a command spends from: its name, and for teleop its robot."""
    name = content.get("command")
    name = name if isinstance(name, str) and len(name) <= 40 else "?"
    if name == "teleop":
        robot = content.get("robot")
        return (name, robot if isinstance(robot, int) and not isinstance(robot, bool) else "?")
    return (name,)
