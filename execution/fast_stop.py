"""A stop from a page's WebSocket leaves before any database work: stop flags, then zero velocities, from the loop.

The web process keeps each robot's command surface in memory (robots/commands.py: endpoint, move topic and
type, ROS version, the move_base cancel topic), loaded in one query and reloaded in the background when older than RELOAD_S. A stop
raises the robots' Redis stop flags (a running instruction sees them on its next tick and publishes nothing
more), then publishes a zero velocity, and cancels a move_base goal, to every robot at once on this loop's own
rosbridge links (robots.rosbridge.pool).

This is only a head start: control.stop then runs in a thread as it always did (checks, flags, a second zero
that changes nothing, queued instructions cancelled, audit) and its answer is what the person reads. A robot
registered since the last load (a registration's push, or a stop naming it, reloads them at once), or a link not
up yet, is stopped by that second step alone.
"""

from __future__ import annotations

import asyncio
import logging
import time

from asgiref.sync import SyncToAsync, async_to_sync
from channels.db import database_sync_to_async

from robots.commands import CommandSurface, surfaces

log = logging.getLogger(__name__)

RELOAD_S = 10.0


def load_targets() -> dict[int, CommandSurface]:
    """Every robot's command surface (one query for robots and bindings); robots without a move topic are left out."""
    from robots.models import Robot

    found = surfaces(Robot.objects.prefetch_related("bindings"))
    return {pk: surface for pk, surface in found.items() if surface.can_move}


class Targets:
    """The process's stop targets, reloaded in the background when stale (never on a stop's way)."""

    def __init__(self) -> None:
        self.by_robot: dict[int, CommandSurface] = {}
        self.loaded_at = float("-inf")
        self.loading: asyncio.Task | None = None

    def refresh(self, now: bool = False) -> None:
        """Reload in the background if stale (now: at once), and open the links stops will use (on this loop)."""
        current = self.loading is not None and self.loading.get_loop() is asyncio.get_running_loop()
        if current and not self.loading.done():
            return
        if current and not now and time.monotonic() - self.loaded_at < RELOAD_S:
            return
        self.loading = asyncio.ensure_future(self._load())

    async def _load(self) -> None:
        from robots.rosbridge import pool

        try:
            self.by_robot = await database_sync_to_async(load_targets, thread_sensitive=False)()
        except Exception:  # the database is away: stops still go the full way
            log.exception("loading stop targets failed")
            return
        self.loaded_at = time.monotonic()
        for endpoint in {target.endpoint for target in self.by_robot.values()}:
            opening = asyncio.ensure_future(pool.client(endpoint, connect_timeout=5.0))
            opening.add_done_callback(_quiet)  # a robot that is down is said by the stop itself

    def ids(self, names) -> list[int] | str:
        """The ids of the robots with these names ("all" stays "all"); names not known here are left out."""
        if names == "all":
            return "all"
        wanted = set(names)
        return [target.robot_id for target in self.by_robot.values() if target.name in wanted]

    def knows(self, names) -> bool:
        return set(names) <= {target.name for target in self.by_robot.values()}

    def load_now(self) -> None:
        """Load the targets in this thread (a process that never had a page socket: the CLI, a worker)."""
        self.by_robot = load_targets()
        self.loaded_at = time.monotonic()

    def of(self, robot_ids) -> list[CommandSurface]:
        if robot_ids == "all":
            return list(self.by_robot.values())
        return [self.by_robot[pk] for pk in robot_ids if pk in self.by_robot]


def _quiet(task: asyncio.Task) -> None:
    if not task.cancelled():
        task.exception()


TARGETS = Targets()


async def stop_now(robot_ids) -> int:
    """Flags, then a zero velocity to each known robot whose link is up; how many zeros went out."""
    from execution import coordination
    from robots.rosbridge import pool

    targets = TARGETS.of(robot_ids)
    TARGETS.refresh(now=robot_ids != "all" and len(targets) < len(robot_ids))  # robots new since the load
    if not targets:
        return 0
    await coordination.arequest_stop([target.robot_id for target in targets])

    async def zero(target: CommandSurface) -> bool:
        try:
            link = await pool.client(target.endpoint, connect_timeout=0.0)  # up now, or skipped
            for topic, message, type_ in target.zero():
                await link.publish(topic, message, type_)
        except Exception as exc:  # not up yet, or down: control.stop tries it next and says why
            log.info("fast stop of robot %s skipped: %s", target.robot_id, exc)
            return False
        return True

    return sum(await asyncio.gather(*(zero(target) for target in targets)))


def stop_blocking(names=None, robot_ids=None, timeout: float = 2.0) -> int:
    """stop_now for synchronous callers (the API, the CLI, a worker): flags and zeros before any database write.

    names (or "all") or robot_ids. Inside an ASGI request (a view running in a thread of the web process) it runs
    on the web process's own loop, whose links the pages keep up; elsewhere on this process's rosbridge loop
    thread (robots.rosbridge.sync), loading the targets first if this process never did, or again when a name
    is not among them (a robot registered since). An unreachable robot never delays the others: each zero is
    sent on its own link, none waits for a connection (connect_timeout 0).
    """
    if not TARGETS.by_robot or (names not in (None, "all") and not TARGETS.knows(names)):
        TARGETS.load_now()
    if robot_ids is None:
        robot_ids = TARGETS.ids(names)
    if getattr(SyncToAsync.threadlocal, "main_event_loop", None) is not None:
        return async_to_sync(stop_now)(robot_ids)
    from robots.rosbridge import sync

    return sync.run(stop_now(robot_ids), timeout)
