"""A page socket's sensor feeds: a robot's laser scan and camera, followed while a page shows them.

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

log = logging.getLogger(__name__)

EVERY_MS = {"scan": 500, "camera": 500}  # at most 2 Hz each to a page
BUILD = {"scan": live.scan, "camera": live.camera}


def _feeds_of(robot_id: int):
    """(endpoint, {kind: robots.sensors.Feed}) of a robot, or None if there is no such robot."""
    from robots import sensors
    from robots.models import Robot

    robot = Robot.objects.filter(pk=robot_id).prefetch_related("bindings").first()
    return None if robot is None else (robot.endpoint, sensors.feeds(robot))


class Feeds:
    """The feeds one socket follows: one robot at a time."""

    def __init__(self, send_json: Callable[[dict], Awaitable[None]]) -> None:
        self.send_json = send_json
        self.subs: list[tuple[object, object]] = []  # (client, subscription)
        self.sending: set[str] = set()
        self.robot_id: int | None = None

    async def watch(self, robot_id: int | None, kinds=("scan", "camera")) -> None:
        """Follow these feeds of one robot instead of what was followed (None: follow nothing)."""
        await self.close()
        self.robot_id = robot_id
        if robot_id is None:
            return
        found = await database_sync_to_async(_feeds_of, thread_sensitive=False)(robot_id)
        if found is None or self.robot_id != robot_id:
            return
        url, feeds = found
        wanted = [(kind, feeds[kind]) for kind in kinds if kind in feeds]
        if not wanted:
            return
        from robots.rosbridge import pool

        client = await pool.get(url)  # connects in the background; subscriptions go out once it is up
        for kind, feed in wanted:
            callback = self._forward(kind, robot_id, feed.topic)
            sub = await client.subscribe(
                feed.topic, feed.type, callback, throttle_rate=EVERY_MS[kind], queue_length=1
            )
            self.subs.append((client, sub))

    def _forward(self, kind: str, robot_id: int, topic: str) -> Callable[[dict], None]:
        loop = asyncio.get_running_loop()

        def on_message(message: dict) -> None:
            if kind in self.sending or self.robot_id != robot_id:
                return  # the page has not taken the last one yet: this one is dropped
            self.sending.add(kind)
            task = loop.create_task(self._send(kind, BUILD[kind](robot_id, topic, message)))
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
