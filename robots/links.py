"""Liveness: one long-lived rosbridge link per registered endpoint, shared by the robots behind it.

Each link is a reconnecting RosbridgeClient (backoff 0.1 s doubling to 1.6 s, WebSocket pings every second),
so a restarted endpoint is back within about 2 s and every subscription made on the link is renewed by the
client itself. A change of link state is written to the endpoint's robots (link_status, last_seen) and pushed
through live.robot_status at once; last_seen of online robots is refreshed every HEARTBEAT seconds.

A link survives anything one endpoint sends (robots.rosbridge.client): a frame with wrong fields is dropped
and logged, a frame that is not rosbridge or larger than the frame limit closes the connection and the link
reconnects, and an error in a hook, a callback or the reader is logged, never raised through the supervisor.
A robot that drops while moving: its executor learns "link lost" at its next command, where
fleet/execution/link.py RobotLink.velocity() publishes through the process's SyncClient and gets LinkDown
("…: not connected"), or, between commands, when next_pose() waits past the step's odometry timeout.

Extending: pass `hooks` to LinkManager; each hook is `async hook(client, robots)` and runs once when a link is
created (robots: [{id, name, namespace, bindings: {action: (target, type)}}]). Subscriptions a hook makes
survive reconnections (e.g. the pose stream subscribes each robot's odometry binding here).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable, Iterable

from asgiref.sync import sync_to_async
from django.db import close_old_connections
from django.utils import timezone

import live
from fleetcore.states import Event
from robots.models import Robot
from robots.rosbridge import RosbridgeClient

log = logging.getLogger("robots.links")
HEARTBEAT = 10.0  # seconds between last_seen refreshes of online robots
REFRESH = 5.0  # seconds between looks for newly registered endpoints

Hook = Callable[[RosbridgeClient, list[dict]], Awaitable[None]]


def endpoint_robots(url: str) -> list[dict]:
    """The robots behind one endpoint, with their bindings, as plain dicts for hooks."""
    robots = Robot.objects.filter(endpoint=url).prefetch_related("bindings")
    return [
        {
            "id": r.pk,
            "name": r.name,
            "namespace": r.namespace,
            "bindings": {b.action: (b.target, b.message_type) for b in r.bindings.all() if b.target},
        }
        for r in robots
    ]


def set_link_status(url: str, up: bool) -> list[str]:
    """Write the endpoint's robots' link status and push each change; return the robots changed."""
    close_old_connections()
    status = Robot.Link.ONLINE if up else Robot.Link.OFFLINE
    now = timezone.now()
    changed = []
    for robot in Robot.objects.filter(endpoint=url).exclude(link_status=status):
        robot.link_status = status
        if up:
            robot.last_seen = now
        robot.save(update_fields=["link_status", "last_seen", "updated_at"])
        live.robot_status(robot)
        changed.append(robot.name)
    follow_link_in_state_machine(url, up)
    return changed


def follow_link_in_state_machine(url: str, up: bool) -> None:
    """A link that comes up makes a registered or offline robot ready; a link that drops makes it offline."""
    waiting = [Robot.State.REGISTERED, Robot.State.OFFLINE]
    robots = Robot.objects.filter(endpoint=url)
    robots = robots.filter(state__in=waiting) if up else robots.exclude(state=Robot.State.OFFLINE)
    for robot in robots:
        robot.transition(Event.LINK_UP if up else Event.LINK_DOWN, "link up" if up else "link lost")


def touch(urls: Iterable[str]) -> None:
    """Refresh last_seen of the online robots behind these endpoints (no push: nothing changed)."""
    close_old_connections()
    Robot.objects.filter(endpoint__in=list(urls), link_status=Robot.Link.ONLINE).update(
        last_seen=timezone.now()
    )


def registered_endpoints() -> list[str]:
    close_old_connections()
    return sorted(set(Robot.objects.values_list("endpoint", flat=True)))


class LinkManager:
    """Keep one link per endpoint until stop() is called."""

    def __init__(self, endpoints: Iterable[str] | None = None, hooks: Iterable[Hook] = ()) -> None:
        self.fixed = list(endpoints) if endpoints is not None else None
        self.hooks = list(hooks)
        self.links: dict[str, RosbridgeClient] = {}
        self.changes: asyncio.Queue[tuple[str, bool]] = asyncio.Queue()
        self.stopping = asyncio.Event()

    async def run(self) -> None:
        """Run until stop(): add links for endpoints, write status changes, refresh last_seen."""
        writer = asyncio.create_task(self._write_changes())
        try:
            while not self.stopping.is_set():
                try:
                    await self._tick()
                except Exception:  # the database away, say: log it and look again next time
                    log.exception("links: one round of looking after the endpoints failed")
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self.stopping.wait(), min(REFRESH, HEARTBEAT))
        finally:
            for client in self.links.values():
                await client.close()
            await self.changes.join()
            writer.cancel()

    async def _tick(self) -> None:
        """Add links for new endpoints (each on its own: one that fails does not stop the rest), touch the online."""
        wanted = self.fixed if self.fixed is not None else await sync_to_async(registered_endpoints)()
        for url in wanted:
            if url not in self.links:
                try:
                    await self.add(url)
                except Exception:
                    log.exception("%s: could not start its link", url)
        online = [u for u, c in self.links.items() if c.is_connected]
        await sync_to_async(touch)(online)

    async def add(self, url: str) -> RosbridgeClient:
        """Open a link to url and run the hooks on it (robots read first: if that fails, the next round retries)."""
        robots = await sync_to_async(endpoint_robots)(url) if self.hooks else []
        client = RosbridgeClient(url, reconnect=True, ping_interval=1.0, max_backoff=1.6)
        client.on_link(lambda up, reason, url=url: self._changed(url, up, reason))
        self.links[url] = client
        await client.start()
        if self.hooks:
            for hook in self.hooks:
                try:
                    await hook(client, robots)
                except Exception:
                    log.exception("%s: link hook %r failed", url, hook)
        return client

    def stop(self) -> None:
        self.stopping.set()

    def _changed(self, url: str, up: bool, reason: str) -> None:
        log.info("%s: link %s (%s)", url, "up" if up else "down", reason)
        self.changes.put_nowait((url, up))

    async def _write_changes(self) -> None:
        while True:
            url, up = await self.changes.get()
            try:
                await sync_to_async(set_link_status)(url, up)
            except Exception:
                log.exception("%s: could not store link status", url)
            finally:
                self.changes.task_done()


async def wait_for_endpoints(
    urls: list[str], timeout: float, stopping: asyncio.Event | None = None
) -> list[str]:
    """Wait until each endpoint accepts a WebSocket (the simulator may start later); return those that do."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    ready: list[str] = []
    pending = list(urls)
    delay = 0.1
    while pending and loop.time() < deadline and not (stopping and stopping.is_set()):
        for url in list(pending):
            client = RosbridgeClient(url, connect_timeout=1.0)
            with contextlib.suppress(Exception):
                await client.connect()
                ready.append(url)
                pending.remove(url)
            await client.close()
        if pending:
            await asyncio.sleep(delay)
            delay = min(delay * 2, 1.0)
    return [u for u in urls if u in ready]
