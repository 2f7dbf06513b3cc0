"""A stop leaves before any database work: zero velocities from an event loop, then the stop flags.

The web process keeps each robot's command surface in memory (robots/commands.py: endpoint, move topic and
type, ROS version, the move_base cancel topic), loaded in one query and reloaded in the background when older
than RELOAD_S. A stop publishes a zero velocity, and cancels its navigation goal (move_base or nav2), to every robot at once on this
loop's own rosbridge links (robots.rosbridge.pool), then raises the robots' Redis stop flags (a running
instruction sees them on its next tick and publishes nothing more), within a bound: the zero depends on nothing
but the link, so a Redis that is frozen or refuses writes never holds it back.

This is only a head start: control.stop then runs in a thread as it always did (checks, flags, a second zero
that changes nothing, queued instructions cancelled, audit) and its answer is what the person reads. A robot
registered since the last load (a registration's push, or a stop naming it, reloads them at once) is stopped by
that second step alone; a link not up yet on this loop is asked of the portal's links process (its stop socket,
robots/stopsocket.py), which keeps every link up.
"""

from __future__ import annotations

import asyncio
import logging
import time

from asgiref.sync import SyncToAsync, async_to_sync
from channels.db import database_sync_to_async

from execution import coordination
from robots import commands, stopsocket
from robots.commands import CommandSurface, kept_surfaces, marked_rows
from robots.models import Robot
from robots.rosbridge import pool, sync

log = logging.getLogger(__name__)

RELOAD_S = 10.0


def load_targets() -> dict[int, CommandSurface]:
    """Every robot's command surface (one query; bindings read only for robots changed since the last load,
    robots.commands.kept_surfaces); robots without a move topic are left out."""
    found = kept_surfaces(marked_rows(Robot.objects.all()))
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


FRESH_CONNECT_S = 1.0  # s a process with no link up yet (a fresh CLI) waits at most for each robot's link


_ASKING: set[asyncio.Future] = set()  # the portal asks in flight (a reference each, till they end)


async def stop_now(robot_ids, connect_timeout: float = 0.0) -> int:
    """A zero velocity (and a move_base cancel) to each known robot whose link is up, then the stop flags; how
    many zeros went out.

    The zeros leave first and depend on nothing but the links: the flags (Redis) follow, bounded, and a Redis
    that is frozen or refuses writes is logged, never raised (control.stop raises them again and says so).
    connect_timeout: how long a link that is not up yet may be waited for (0: skipped, as on a page's loop).
    The robots whose link was not up are asked of the running portal's links process too (by_portal, in a
    thread, not waited for): a fresh web process's first stop gets its head start from links already up.
    """
    targets = TARGETS.of(robot_ids)
    TARGETS.refresh(now=robot_ids != "all" and len(targets) < len(robot_ids))  # robots new since the load
    if not targets:
        return 0
    began = time.monotonic()
    zeros = [asyncio.ensure_future(_zero(target, connect_timeout)) for target in targets]
    flags = asyncio.ensure_future(coordination.arequest_stop([target.robot_id for target in targets]))
    went = await asyncio.gather(*zeros)
    log.info(
        "fast stop: %d of %d zeros out in %.1f ms", sum(went), len(targets), 1000 * (time.monotonic() - began)
    )
    missed = sorted(target.name for target, out in zip(targets, went, strict=True) if not out)
    # links this loop has not up yet (a web process's first stop): the portal's links process has them
    if missed:
        _ASKING.add(asking := asyncio.ensure_future(asyncio.to_thread(by_portal, missed)))
        asking.add_done_callback(_ASKING.discard)
    sent = sum(went)
    try:
        await flags
    except Exception as exc:  # Redis frozen, away or refusing writes: the zeros are out all the same
        log.warning("stop flags not raised (the zeros went out): %r", exc)
    return sent


async def _zero(target: CommandSurface, connect_timeout: float) -> bool:
    """Publish the robot's zero on this loop's link; False (logged) when the link is not up in time."""
    try:
        link = await pool.client(target.endpoint, connect_timeout=connect_timeout)
        await commands.send(link, target.zero())  # a nav2 goal's cancel is not waited for
    except Exception as exc:  # not up yet, or down: control.stop tries it next and says why
        log.info("fast stop of robot %s skipped: %s", target.robot_id, exc)
        return False
    return True


def by_portal(names) -> dict | None:
    """Ask the running portal's links process to zero these robots ("all": every one) on the links it keeps up
    (robots/stopsocket.py: no Redis, no database on the way); its answer ({"zeroed", "missed", "unknown"}),
    or None when no portal runs on this var folder or it does not answer within stopsocket.ASK_TIMEOUT_S."""
    answer = stopsocket.stop(names)
    if answer is not None:
        log.info("stop by the portal's links: zeros to %s", ", ".join(answer["zeroed"]) or "no robot")
    return answer


def stop_blocking(names=None, robot_ids=None, timeout: float = 2.0) -> int:
    """stop_now for synchronous callers (the API, the CLI, a worker): zeros, then flags, before any database write.

    names (or "all") or robot_ids. Inside an ASGI request (a view running in a thread of the web process) it runs
    on the web process's own loop, whose links the pages keep up; elsewhere on this process's rosbridge loop
    thread (robots.rosbridge.sync), loading the targets first if this process never did, or again when a name
    is not among them (a robot registered since); there a link not up yet (a fresh CLI) is waited for, at most
    FRESH_CONNECT_S, each robot's on its own, so an unreachable robot never delays another's zero. Outside a
    request, named robots are first asked of the running portal (by_portal): when its links process zeroed them
    all, that is the stop's head start and no link of this process is waited for. Never raises for a database or
    a link: what was not done is left to control.stop, which says why.
    """
    in_request = getattr(SyncToAsync.threadlocal, "main_event_loop", None) is not None
    if not in_request and robot_ids is None and names is not None:
        answer = by_portal(names)
        if answer is not None and answer["zeroed"] and not answer["missed"] and not answer["unknown"]:
            return len(answer["zeroed"])
    try:
        if not TARGETS.by_robot or (names not in (None, "all") and not TARGETS.knows(names)):
            TARGETS.load_now()
    except Exception:  # the database is away: the targets this process has are used
        log.exception("loading stop targets failed")
    if robot_ids is None:
        robot_ids = TARGETS.ids(names)
    try:
        if in_request:
            return async_to_sync(stop_now)(robot_ids)
        return sync.run(stop_now(robot_ids, FRESH_CONNECT_S), timeout)
    except Exception:
        log.exception("fast stop failed; control.stop stops the robots")
        return 0
