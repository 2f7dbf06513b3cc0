"""The robot page's topic inspector: any topic of the robot's graph, its type, its rate and its latest message.

Only topics the robot's registration found (its graph, robots.Topic) can be picked: the page names one, the
server looks it up, so a page cannot subscribe to anything else on the endpoint. It subscribes, never
publishes: nothing goes to the robot through it, whoever looks (a viewer may). rosbridge throttles the
subscription (throttle_rate, queue_length 1), so a camera at 30 Hz costs at most 10 messages a second here;
the rate is counted from those (said "at least" past half the cap) and the page gets the newest message at
most twice a second, as indented JSON with long arrays and strings shortened. A robot is untrusted: its message
is data the page shows as text, never markup.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import deque
from collections.abc import Awaitable, Callable

from channels.db import database_sync_to_async

import live
from robots.models import Topic
from robots.rosbridge import pool

log = logging.getLogger(__name__)

THROTTLE_MS = 100  # rosbridge sends at most one message each 100 ms: the rate is measured up to 10 Hz
# Past half the cap, rosbridge's throttle drops some (a 20 Hz topic arrives at 7-10 Hz): "at least" that rate.
CAPPED_HZ = 1000 / THROTTLE_MS / 2
SEND_S = 0.5  # the page gets the newest message at most twice a second
WINDOW_S = 5.0  # the rate is counted over the last five seconds
ARRAY_SHOWN, STRING_SHOWN, TEXT_MAX = 12, 200, 8000
TOPIC_MAX = 256


class NotInspectable(ValueError):
    """The page named a topic the robot does not have (or no robot); the message says so."""


def _topic_of(robot_id: int, topic: str):
    """(endpoint, type) of one topic of the robot's graph; NotInspectable otherwise."""
    found = Topic.objects.filter(robot_id=robot_id, name=topic).select_related("robot").first()
    if found is None:
        raise NotInspectable(f"{topic[:TOPIC_MAX]}: not a topic of this robot")
    return found.robot.endpoint, found.type


def shortened(value, depth: int = 0):
    """The message for reading: arrays past ARRAY_SHOWN items and strings past STRING_SHOWN characters cut,
    with how much was left out (an image's data, a scan's ranges)."""
    if depth > 12:
        return "…"
    if isinstance(value, dict):
        return {
            str(key)[:STRING_SHOWN]: shortened(item, depth + 1) for key, item in list(value.items())[:100]
        }
    if isinstance(value, list):
        head = [shortened(item, depth + 1) for item in value[:ARRAY_SHOWN]]
        return head + ([f"… {len(value) - ARRAY_SHOWN} more"] if len(value) > ARRAY_SHOWN else [])
    if isinstance(value, str) and len(value) > STRING_SHOWN:
        return f"{value[:STRING_SHOWN]}… ({len(value)} characters)"
    return value


def as_text(message) -> str:
    text = json.dumps(shortened(message), indent=1, ensure_ascii=False, allow_nan=True)
    return text if len(text) <= TEXT_MAX else f"{text[:TEXT_MAX]}\n… ({len(text)} characters)"


class Rate:
    """Messages a second over the last WINDOW_S seconds."""

    def __init__(self) -> None:
        self.seen: deque[float] = deque()
        self.count = 0

    def add(self, now: float) -> None:
        self.count += 1
        self.seen.append(now)
        while self.seen and self.seen[0] < now - WINDOW_S:
            self.seen.popleft()

    def words(self) -> dict:
        if len(self.seen) < 2 or self.seen[-1] <= self.seen[0]:
            return {"rate_hz": None, "capped": False, "count": self.count}
        hz = (len(self.seen) - 1) / (self.seen[-1] - self.seen[0])
        return {"rate_hz": round(hz, 2), "capped": hz > CAPPED_HZ, "count": self.count}


class Inspector:
    """One socket's inspector: one topic of its robot at a time."""

    def __init__(self, robot_id: int, send_json: Callable[[dict], Awaitable[None]]) -> None:
        self.robot_id = robot_id
        self.send_json = send_json
        self.sub: tuple[object, object] | None = None
        self.topic: str | None = None

    async def inspect(self, topic) -> str:
        """Follow this topic instead of what was followed (None or "": nothing); the answer in words."""
        await self.close()
        if topic in (None, ""):
            return "inspector off"
        if not isinstance(topic, str) or len(topic) > TOPIC_MAX:
            raise NotInspectable("topic: a topic name of the robot")
        url, msg_type = await database_sync_to_async(_topic_of, thread_sensitive=False)(self.robot_id, topic)
        self.topic = topic
        client = await pool.get(url)
        callback = self._on_message(topic, msg_type)
        sub = await client.subscribe(topic, msg_type, callback, throttle_rate=THROTTLE_MS, queue_length=1)
        self.sub = (client, sub)
        return f"inspecting {topic} ({msg_type})"

    def _on_message(self, topic: str, msg_type: str) -> Callable[[dict], None]:
        loop = asyncio.get_running_loop()
        rate = Rate()
        state = {"sent": 0.0, "sending": False}

        def on_message(message) -> None:
            now = time.monotonic()
            rate.add(now)
            if self.topic != topic or state["sending"] or now - state["sent"] < SEND_S:
                return
            state["sent"], state["sending"] = now, True
            payload = live.topic_message(self.robot_id, topic, msg_type, rate.words(), as_text(message))
            task = loop.create_task(self._send(payload))
            task.add_done_callback(lambda _done: state.update(sending=False))

        return on_message

    async def _send(self, payload: dict) -> None:
        try:
            await self.send_json(payload)
        except Exception as exc:  # the socket closed meanwhile
            log.debug("inspector frame not sent: %r", exc)

    async def close(self) -> None:
        sub, self.sub, self.topic = self.sub, None, None
        if sub is not None:
            with contextlib.suppress(Exception):
                await sub[0].unsubscribe(sub[1])
