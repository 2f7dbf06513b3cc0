"""A page socket's sensor feeds: a robot's laser scan, camera and diagnostics, followed while a page shows them.

Subscribed on the web process's own rosbridge link to the robot's endpoint (robots.rosbridge.pool), throttled by
rosbridge itself, and forwarded as live's payloads (live.scan, live.camera) on the socket that asked. A page
that is slow to take them drops frames (the newest comes next), never queues them. The robot's page follows
its robot's scan and camera; the dashboard's map follows the scan of the robot it is showing (a "watch").
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable

from channels.db import database_sync_to_async

import live
from robots import sensors
from robots.models import Robot
from robots.rosbridge import pool

log = logging.getLogger(__name__)

# At most 2 Hz each to a page. Robots sharing an endpoint share /diagnostics (each node its own array once a
# second): up to 20 arrays a second pass, rosbridge queues ten more (its QueueMessageHandler), and only this
# robot's statuses go on to the page.
EVERY_MS = {"scan": 500, "camera": 500, "diagnostics": 50}
QUEUE = {"scan": 1, "camera": 1, "diagnostics": 10}
KINDS = ("scan", "camera", "diagnostics")


def _feeds_of(robot_id: int):
    """(endpoint, {kind: robots.sensors.Feed}, DiagnosticsOwner) of a robot, or None if there is no such robot."""
    robot = Robot.objects.filter(pk=robot_id).prefetch_related("bindings").first()
    if robot is None:
        return None
    return robot.endpoint, sensors.feeds(robot), sensors.DiagnosticsOwner.of(robot)


def _builder(kind: str, owner) -> Callable[[int, str, dict], dict | None]:
    """What a message of this kind becomes on the page (None: nothing of this robot's in it)."""
    if kind != "diagnostics":
        return {"scan": live.scan, "camera": live.camera}[kind]

    def build(robot_id: int, topic: str, message: dict) -> dict | None:
        statuses = message.get("status") if isinstance(message.get("status"), list) else []
        mine = [status for status in statuses if isinstance(status, dict) and owner.owns(status)]
        return live.diagnostics(robot_id, topic, mine) if mine else None

    return build


class Feeds:
    """The feeds one socket follows: one robot at a time."""

    def __init__(self, send_json: Callable[[dict], Awaitable[None]]) -> None:
        self.send_json = send_json
        self.subs: list[tuple[object, object]] = []  # (client, subscription)
        self.sending: set[str] = set()
        self.robot_id: int | None = None

    async def watch(self, robot_id: int | None, kinds=KINDS) -> None:
        """Follow these feeds of one robot instead of what was followed (None: follow nothing)."""
        await self.close()
        self.robot_id = robot_id
        if robot_id is None:
            return
        found = await database_sync_to_async(_feeds_of, thread_sensitive=False)(robot_id)
        if found is None or self.robot_id != robot_id:
            return
        url, feeds, owner = found
        wanted = [(kind, feeds[kind]) for kind in kinds if kind in feeds]
        if not wanted:
            return
        client = await pool.get(url)  # connects in the background; subscriptions go out once it is up
        for kind, feed in wanted:
            callback = self._forward(kind, robot_id, feed.topic, _builder(kind, owner))
            sub = await client.subscribe(
                feed.topic, feed.type, callback, throttle_rate=EVERY_MS[kind], queue_length=QUEUE[kind]
            )
            self.subs.append((client, sub))

    def _forward(self, kind: str, robot_id: int, topic: str, build) -> Callable[[dict], None]:
        loop = asyncio.get_running_loop()

        def on_message(message: dict) -> None:
            if kind in self.sending or self.robot_id != robot_id or not isinstance(message, dict):
                return  # the page has not taken the last one yet: this one is dropped
            payload = build(robot_id, topic, message)
            if payload is None:
                return
            self.sending.add(kind)
            task = loop.create_task(self._send(kind, payload))
            task.add_done_callback(lambda _done: self.sending.discard(kind))

        return on_message

    async def _send(self, kind: str, payload: dict) -> None:
        try:
            await self.send_json(payload)
        except Exception as exc:  # the socket closed meanwhile
            log.debug("%s frame not sent: %r", kind, exc)

    async def close(self) -> None:
        subs, self.subs = self.subs, []
        for client, sub in subs:
            with contextlib.suppress(Exception):
                await client.unsubscribe(sub)
