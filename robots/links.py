"""Liveness: one long-lived rosbridge link per registered endpoint, shared by the robots behind it.

Each link is a reconnecting RosbridgeClient (backoff 0.1 s doubling to 1.6 s, WebSocket pings every second,
PING_TIMEOUT_S for the pong), so a restarted endpoint is back within about 2 s and every subscription made on the
link is renewed by the client itself. A change of link state is written to the endpoint's robots (link_status,
last_seen) and pushed through live.robot_status at once; last_seen of online robots is refreshed every HEARTBEAT
seconds.

A link survives anything one endpoint sends (robots.rosbridge.client): a frame with wrong fields is dropped
and logged, a frame that is not rosbridge or larger than the frame limit closes the connection and the link
reconnects, and an error in a hook, a callback or the reader is logged, never raised through the supervisor.
A robot that drops while moving: its executor fails the step "link lost" (execution/steps.py: its odometry
stops and its link says disconnected, or a command meets the dropped link).

A link that drops raises a robot_offline alert for each robot behind it (resolved when it comes back), and
every robot that was moving then (or whose executor failed its step with "link lost": owe_zero) is sent a
zero velocity as soon as its link is back, before anything else can command it: a base without a command
timeout would otherwise carry on with the last Twist it got. battery_hook raises low_battery alerts from a
bound sensor_msgs/BatteryState.

Extending: pass `hooks` to LinkManager; each hook is `async hook(client, robots)` and runs once when a link is
created (robots: [{id, name, namespace, bindings: {action: (target, type)}}]). Subscriptions a hook makes
survive reconnections (e.g. the pose stream subscribes each robot's odometry binding here).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
from collections.abc import Awaitable, Callable, Iterable

from asgiref.sync import sync_to_async
from django.core.cache import cache
from django.db import close_old_connections
from django.db.models import Count, Max
from django.utils import timezone

import alerts
import live
from fleetcore.states import Event
from robots import commands
from robots.commands import CommandSurface, surface_rows, surfaces
from robots.models import Binding, Robot
from robots.rosbridge import RosbridgeClient

log = logging.getLogger("robots.links")
HEARTBEAT = 10.0  # seconds between last_seen refreshes of online robots
REFRESH = 5.0  # seconds between looks for newly registered endpoints
ZERO_OWED_KEY = "fleet:zero-owed:{id}"
ZERO_OWED_S = 24 * 3600  # a robot away for longer than a day gets no zero when it comes back
MOVING = (Robot.State.MOTION, Robot.State.WORK)
LOW_BATTERY, BATTERY_OK = 0.2, 0.3  # fraction of charge: alert under the first, resolved over the second
BATTERY_EVERY_MS = 10_000  # rosbridge throttle of the battery subscription

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


def owe_zero(robot_ids) -> None:
    """Remember to send these robots a zero velocity when their link is back (an executor lost its link)."""
    cache.set_many({ZERO_OWED_KEY.format(id=pk): True for pk in robot_ids}, timeout=ZERO_OWED_S)


def zeros_owed(url: str) -> list[CommandSurface]:
    """The command surfaces of the robots behind url that are owed a zero."""
    close_old_connections()
    found = surfaces(surface_rows(Robot.objects.filter(endpoint=url)))
    owed = cache.get_many([ZERO_OWED_KEY.format(id=pk) for pk in found])
    return [s for pk, s in found.items() if ZERO_OWED_KEY.format(id=pk) in owed and s.can_move]


def paid_zero(robot_ids) -> None:
    cache.delete_many([ZERO_OWED_KEY.format(id=pk) for pk in robot_ids])


def set_link_status(url: str, up: bool, reason: str = "") -> list[str]:
    """Write the endpoint's robots' link status, push and alert each change; return the robots changed. The
    pushes (a status and an alert per robot: 1,000 when a 500-robot endpoint comes up) go at the end, each
    group's in one message (live.together)."""
    with live.together():
        return _set_link_status(url, up, reason)


def _set_link_status(url: str, up: bool, reason: str) -> list[str]:
    close_old_connections()
    status = Robot.Link.ONLINE if up else Robot.Link.OFFLINE
    now = timezone.now()
    changed = []
    if not up:  # before the state machine makes them offline: who was moving when the link dropped
        owe_zero(Robot.objects.filter(endpoint=url, state__in=MOVING).values_list("pk", flat=True))
    for robot in Robot.objects.filter(endpoint=url).exclude(link_status=status):
        robot.link_status = status
        if up:
            robot.last_seen = now
        robot.save(update_fields=["link_status", "last_seen", "updated_at"])
        live.robot_status(robot)
        changed.append(robot.name)
        if up:
            alerts.resolve_alert("robot_offline", robot, "link up again")
        else:
            alerts.raise_alert(
                "robot_offline", robot, f"link to {url} lost{f' ({reason})' if reason else ''}"
            )
    if up:
        settle_offline_alerts(url, changed)
    follow_link_in_state_machine(url, up)
    return changed


def settle_offline_alerts(url: str, settled: list[str]) -> None:
    """Resolve the offline alerts still open for robots behind a link that is up, whose status did not change:
    left by a shutdown or a restart of this process (registration had already written them online)."""
    left = Robot.objects.filter(
        endpoint=url, alerts__kind="robot_offline", alerts__resolved_at__isnull=True
    ).exclude(name__in=settled)
    for robot in left.distinct():
        alerts.resolve_alert("robot_offline", robot, "link up (the alert was left open from before)")


async def pay_zeros(client: RosbridgeClient, url: str) -> list[str]:
    """Send every robot behind url that is owed a zero its zero velocity, on the link just back up."""
    owed = await sync_to_async(zeros_owed)(url)
    for robot in owed:
        try:
            await commands.send(client, robot.zero())
        except Exception as exc:  # down again: still owed, paid on the next reconnection
            log.warning("%s: zero for %s not sent: %s", url, robot.name, exc)
            return []
    await sync_to_async(paid_zero)([robot.robot_id for robot in owed])
    if owed:
        log.info("%s: link back, zero velocity sent to %s", url, ", ".join(r.name for r in owed))
    return [robot.name for robot in owed]


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


def stop_targets(urls: Iterable[str]) -> dict[str, CommandSurface]:
    """{robot name: its command surface} of the robots behind these endpoints that can be driven (one query)."""
    close_old_connections()
    found = surfaces(surface_rows(Robot.objects.filter(endpoint__in=list(urls))))
    return {surface.name: surface for surface in found.values() if surface.can_move}


def targets_mark(urls: Iterable[str]) -> tuple:
    """What stop_targets reads, summed up in two small queries: it changes when a robot or a binding behind these
    endpoints is added, deleted or saved (a command surface's fields are written by save() or by registration's
    bulk_update, both of which stamp updated_at; the .update() calls of state, holds and last_seen do not, and a
    surface does not read those)."""
    close_old_connections()
    urls = sorted(urls)
    robots = Robot.objects.filter(endpoint__in=urls).aggregate(n=Count("pk"), at=Max("updated_at"))
    bindings = Binding.objects.filter(robot__endpoint__in=urls).aggregate(n=Count("pk"), at=Max("updated_at"))
    return (tuple(urls), robots["n"], robots["at"], bindings["n"], bindings["at"])


STOP_PUBLISH_S = 0.5  # one robot's zero on a link that is up; a stuck send never holds another robot's


# A pong later than this closes the link (a killed endpoint is noticed at once, by its closed connection; a silent
# one, frozen or cut off, within a second more). At 1 s, a saturated machine (1,000 robots on the cluster) had both
# shards' links closed for pongs a second late: 1,000 robots said offline, instructions refused, every subscription
# made again on top of the load, and whatever was queued on the links lost. A slow link still carries a stop.
PING_TIMEOUT_S = 4.0


def liveness_client(url: str) -> RosbridgeClient:
    """The links process's link to one endpoint (see the module's docstring and PING_TIMEOUT_S)."""
    return RosbridgeClient(
        url, reconnect=True, ping_interval=1.0, ping_timeout=PING_TIMEOUT_S, max_backoff=1.6
    )


class LinkManager:
    """Keep one link per endpoint until stop() is called."""

    def __init__(self, endpoints: Iterable[str] | None = None, hooks: Iterable[Hook] = ()) -> None:
        self.fixed = list(endpoints) if endpoints is not None else None
        self.hooks = list(hooks)
        self.links: dict[str, RosbridgeClient] = {}
        self.changes: asyncio.Queue[tuple[str, bool]] = asyncio.Queue()
        self.stopping = asyncio.Event()
        self.targets: dict[str, CommandSurface] = {}  # by robot name: what a stop asked of us zeroes
        self.targets_mark: tuple | None = None  # targets_mark() when they were built: rebuilt when it changes

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
        """Add links for new endpoints (together, each on its own: one that fails or is slow does not hold the
        rest), touch the online, refresh the stop targets. The reads are not made on Django's shared sync thread,
        where the link status writes queue (a save, an alert and a push per robot: seconds for an endpoint of
        500 robots on a busy machine); in one 1,000-robot run the second shard's link never came up while they
        ran (docs/scale.md, "2026-11-29"). The touch, a write, stays there (SQLite, `make run`'s default, takes
        one writer at a time)."""
        off_thread = functools.partial(sync_to_async, thread_sensitive=False)
        wanted = self.fixed if self.fixed is not None else await off_thread(registered_endpoints)()
        await asyncio.gather(*(self._add_logged(url) for url in wanted if url not in self.links))
        online = [u for u, c in self.links.items() if c.is_connected]
        await sync_to_async(touch)(online)
        mark = await off_thread(targets_mark)(list(self.links))
        if (
            mark != self.targets_mark
        ):  # (building every robot's surface each round was a sixth of this process)
            self.targets = await off_thread(stop_targets)(list(self.links))
            self.targets_mark = mark

    async def _add_logged(self, url: str) -> None:
        try:
            await self.add(url)
        except Exception:
            log.exception("%s: could not start its link", url)

    async def zero(self, names: list[str] | str) -> dict:
        """Publish the zero of each named robot ("all": every one) on its link, all at once, from memory (no
        database, no Redis): {"zeroed": names, "missed": {name: why}, "unknown": names}. A name not known here
        zeroes nothing (the caller's interpretation decides what the text meant)."""
        targets = {name.casefold(): target for name, target in self.targets.items()}
        wanted = sorted(targets) if names == "all" else list(dict.fromkeys(n.casefold() for n in names))
        unknown = [name for name in wanted if name not in targets]
        if unknown:
            return {"zeroed": [], "missed": {}, "unknown": unknown}
        wanted = [targets[name].name for name in wanted]
        targets = {target.name: target for target in targets.values()}
        sent = await asyncio.gather(*(self._zero_one(targets[name]) for name in wanted))
        missed = {name: why for name, why in zip(wanted, sent, strict=True) if why}
        return {"zeroed": [name for name in wanted if name not in missed], "missed": missed, "unknown": []}

    async def _zero_one(self, target: CommandSurface) -> str:
        """ "" once the robot's zero is out, else why not."""
        client = self.links.get(target.endpoint)
        if client is None or not client.is_connected:
            return "its link is not up"
        try:
            async with asyncio.timeout(STOP_PUBLISH_S):
                await commands.send(client, target.zero())  # a nav2 goal's cancel is not waited for
        except Exception as exc:  # down meanwhile, or stuck: the caller stops it on its own link
            return f"not sent: {exc!r}"
        return ""

    def linked(self) -> list[str]:
        """The robots whose link is up now."""
        return sorted(name for name, t in self.targets.items() if self._up(t.endpoint))

    def _up(self, url: str) -> bool:
        client = self.links.get(url)
        return client is not None and client.is_connected

    async def add(self, url: str) -> RosbridgeClient:
        """Open a link to url and run the hooks on it (robots read first: if that fails, the next round retries)."""
        # not on Django's shared sync thread, where the link status writes (a push per robot) queue
        robots = await sync_to_async(endpoint_robots, thread_sensitive=False)(url) if self.hooks else []
        client = liveness_client(url)
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
        self.changes.put_nowait((url, up, reason))

    async def _write_changes(self) -> None:
        while True:
            url, up, reason = await self.changes.get()
            try:
                if up and url in self.links:
                    await pay_zeros(self.links[url], url)  # first: before the status lets anyone command it
                await sync_to_async(set_link_status)(url, up, reason)
            except Exception:
                log.exception("%s: could not store link status", url)
            finally:
                self.changes.task_done()


_BATTERY_CHECKS: set[asyncio.Task] = set()  # running checks, kept until done


async def battery_hook(client: RosbridgeClient, robots: list[dict]) -> None:
    """A LinkManager hook: follow each robot's bound battery (sensor_msgs/BatteryState), every 10 s at most.

    The charge is classed on the loop ("low", "ok" or neither); the database is reached only when a robot's class
    changes (the first message of each robot counts as a change, so an alert left open from before is resolved).
    With 1,000 robots a check per message was 100 transactions a second through Django's one shared sync
    thread, where the pose hub's writes queued behind them: the live push all but stopped."""
    loop = asyncio.get_running_loop()
    last: dict[int, str] = {}
    for robot in robots:
        if "battery" not in robot["bindings"]:
            continue
        topic, type_ = robot["bindings"]["battery"]

        def on_battery(message: dict, robot_id=robot["id"]) -> None:
            level = battery_level(message)
            if level is None or last.get(robot_id) == level:
                return
            last[robot_id] = level
            task = loop.create_task(sync_to_async(check_battery, thread_sensitive=False)(robot_id, message))
            _BATTERY_CHECKS.add(task)
            task.add_done_callback(_BATTERY_CHECKS.discard)

        await client.subscribe(
            topic, type_ or "sensor_msgs/BatteryState", on_battery, throttle_rate=BATTERY_EVERY_MS
        )


def battery_charge(message: dict) -> float | None:
    """The charge as a fraction of 1, or None when unknown (NaN is "not measured" in BatteryState)."""
    charge = message.get("percentage") if isinstance(message, dict) else None
    if isinstance(charge, bool) or not isinstance(charge, int | float) or not math.isfinite(charge):
        return None
    return charge / 100 if charge > 1 else charge  # some drivers publish percent, not a fraction


def battery_level(message: dict) -> str | None:
    """ "low" under LOW_BATTERY, "ok" over BATTERY_OK, None between them or when the charge is unknown."""
    charge = battery_charge(message)
    if charge is None:
        return None
    return "low" if charge < LOW_BATTERY else "ok" if charge > BATTERY_OK else None


def check_battery(robot_id: int, message: dict) -> str | None:
    """Raise low_battery under LOW_BATTERY, resolve it over BATTERY_OK; return "low", "ok" or None."""
    level = battery_level(message)
    if level is None:
        return None
    charge = battery_charge(message)
    close_old_connections()
    robot = Robot.objects.filter(pk=robot_id).first()
    if robot is None:
        return None
    if level == "low":
        alerts.raise_alert("low_battery", robot, f"{robot.name}: battery at {charge:.0%}")
    else:
        alerts.resolve_alert("low_battery", robot, f"battery at {charge:.0%}")
    return level


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
