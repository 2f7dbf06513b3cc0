"""Live poses: each robot's odometry (and amcl pose) becomes a map pose, coalesced, pushed at up to 10 Hz.

A robot's map pose is its odometry composed with its start pose (the odometry origin on the map); once an
amcl pose arrives, the map->odom offset is corrected from it, so later odometry stays on the map.

Odometry passes the robot's gate first (fleetcore.posegate: no NaN or infinity, no jump faster than the robot,
no stamp from the future). A refused message leaves the last good pose in place and flags it: the pose carries
`fault` (the reason) and `fault_since` until the odometry is good again, and an odometry_invalid alert is raised
(resolved when it is good again). Each pose carries `t`, when it was taken: its age is how stale it is.

How the link process (``manage.py robotlinks``) drives it::

    hub = PoseHub()                                   # one per process, in its event loop
    manager = LinkManager(hooks=[link_hook(hub)])     # subscribes odometry (and amcl pose) per robot
    await asyncio.gather(manager.run(), hub.run(stop)) # one batched "fleet.poses" message per tick

Callbacks take the decoded ROS message (a dict) and may be called from any thread. ``link_hook(hub)`` does
the subscribing on the links process's own rosbridge links; without a link process, ``follow(robots, hub,
stop)`` opens one link per endpoint itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections import defaultdict
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from datetime import UTC, datetime

from asgiref.sync import sync_to_async
from channels.layers import get_channel_layer
from django.core.cache import cache
from django.db import close_old_connections
from django.utils import timezone

import alerts
import live
from fleetcore.geometry import Pose2D, compose, inverse, pose_of, start_offset
from fleetcore.posegate import InvalidOdometry, PoseGate
from robots.models import Robot
from robots.rosbridge.client import RosbridgeClient
from robots.rosbridge.errors import RosbridgeError

log = logging.getLogger(__name__)

DEFAULT_RATE_HZ = 10.0
BATTERY_EVERY_MS = 1000  # rosbridge throttle of a battery subscription for the pages (charge moves slowly)
ROUND_TRIP_EVERY_S = 2.0  # a ping on each endpoint's link this often


@dataclass(frozen=True)
class Subscription:
    """One topic a link should subscribe for the hub, with the callback that takes its messages."""

    robot_id: int
    topic: str
    msg_type: str
    callback: Callable[[dict], None]
    throttle_rate: int  # milliseconds, as rosbridge's subscribe op takes it
    queue_length: int = 1  # the newest each throttle (see PoseHub.subscriptions)


POSE_TTL_S = 60  # a robot not heard of for this long has no last pose
STALE_S = 2.0  # a pose older than this is stale: the page, the API and the answers say so, with its age
POSES_KEY = "fleet:poses"  # one hash in the cache: a field per robot (its id), its last pose


def store_poses(batch: list[live.RobotPose]) -> None:
    """Keep the latest map pose of each robot: the one store of "where is robot X" (pages, dispatch, routes).
    One write for the batch (fleet.cache: a field of one hash per robot)."""
    cache.hash_set(POSES_KEY, {pose["id"]: pose for pose in batch}, timeout=POSE_TTL_S)


def store_pose(robot_id: int, pose: Pose2D) -> None:
    """Keep one robot's pose (an executor's own odometry, between the pose hub's ticks), taken now."""
    x, y, yaw = pose
    store_poses(
        [{"id": robot_id, "x": round(x, 3), "y": round(y, 3), "yaw": round(yaw, 4), "t": time.time()}]
    )


def forget_poses(robot_ids) -> None:
    """These robots have no last pose any more (a test's own poses). A removed robot's field is left: nothing
    asks for its id again, and the hash lapses POSE_TTL_S after the fleet's last pose."""
    cache.hash_delete(POSES_KEY, robot_ids)


def kept_poses(robot_ids) -> dict[int, dict]:
    """{robot id: its kept pose record} (a refused odometry's with its `fault`), but for one taken more than
    POSE_TTL_S ago: that robot is not heard of. Raises when the cache is away."""
    oldest = time.time() - POSE_TTL_S
    return {
        pose["id"]: pose
        for pose in cache.hash_get(POSES_KEY, robot_ids).values()
        if isinstance(pose, dict) and "id" in pose and pose.get("t", oldest) >= oldest
    }


def _cached(robot_ids) -> list[dict]:
    try:
        return list(kept_poses(robot_ids).values())
    except Exception:  # the cache is away: no pose is known, callers plan without them
        log.warning("last poses unavailable", exc_info=True)
        return []


def last_poses(robot_ids) -> dict[int, dict]:
    """{robot id: {"id", "x", "y", "yaw", ...}} for the robots whose pose is known (the last good one of a
    robot whose odometry is refused now, with its `fault`)."""
    return {pose["id"]: pose for pose in _cached(robot_ids) if "x" in pose}


def start_of(robot) -> dict | None:
    """The pose a robot started from (Robot.start_pose: found at registration, or its world's), as a pose."""
    pose = robot.start_pose
    if not pose or len(pose) < 2:
        return None
    return {
        "id": robot.pk,
        "x": float(pose[0]),
        "y": float(pose[1]),
        "yaw": float(pose[2]) if len(pose) > 2 else 0.0,
    }


def known_poses(robots) -> dict[int, dict]:
    """Where each of these robots is as far as the fleet knows: its last pose (last_poses), else where it started
    (start_of). A robot that has not moved since it was registered, where no pose hub runs or before its first
    tick, still has a place: dispatch chose the nearest robot by it, and a spot given to it near a taken place
    is on its side of the place (without one, on the place's east side: "turtlebot to tiago" was given a spot
    beyond tiago's doorway, which it could not reach)."""
    robots = list(robots)
    known = last_poses([robot.pk for robot in robots])
    for robot in robots:
        if robot.pk not in known and (start := start_of(robot)) is not None:
            known[robot.pk] = start
    return known


def pose_faults(robot_ids) -> dict[int, dict]:
    """{robot id: its last pose record} for the robots whose odometry the gate refuses now ("fault", "fault_since")."""
    return {pose["id"]: pose for pose in _cached(robot_ids) if pose.get("fault")}


def clock_words(unix: float | None) -> str:
    """A unix time as the local wall clock a person reads ("10:43:02")."""
    if unix is None:
        return "an unknown time"
    return timezone.localtime(datetime.fromtimestamp(unix, tz=UTC)).strftime("%H:%M:%S")


def fault_words(name: str, pose: dict) -> str:
    """ "robot5's odometry is invalid (x is NaN) since 10:43:02": the one wording of a refused odometry."""
    return f"{name}'s odometry is invalid ({pose['fault']}) since {clock_words(pose.get('fault_since'))}"


def pose_age(pose: dict | None, now: float | None = None) -> float | None:
    """Seconds since the pose was taken; None when it carries no time (or there is none)."""
    if not pose or not isinstance(pose.get("t"), int | float):
        return None
    return max(0.0, (time.time() if now is None else now) - pose["t"])


def pose_words(pose: dict | None, now: float | None = None) -> str:
    """The one wording of a pose's health: "odometry invalid: x is NaN", "stale (3.2 s)", "live" or "no pose"."""
    if pose and pose.get("fault"):
        return f"odometry invalid: {pose['fault']}"
    age = pose_age(pose, now)
    if age is None:
        return "no pose"
    return f"stale ({age:.1f} s)" if age > STALE_S else "live"


def freshness(robots) -> dict[int, dict]:
    """Each robot's pose health as the API says it: {"last_seen", "pose_age", "stale", "pose_fault",
    "pose_status"}. last_seen is the freshest sign of life, the link's heartbeat (written every few seconds,
    and not at all while the links process is stuck) or the last pose (taken up to 10 times a second)."""
    robots = list(robots)
    cached = {pose["id"]: pose for pose in _cached([robot.pk for robot in robots])}
    now = time.time()
    found = {}
    for robot in robots:
        pose = cached.get(robot.pk)
        age = pose_age(pose, now)
        seen = robot.last_seen
        if age is not None and (seen is None or seen.timestamp() < pose["t"]):
            seen = datetime.fromtimestamp(pose["t"], tz=UTC)
        found[robot.pk] = {
            "last_seen": seen,
            "pose_age": None if age is None else round(age, 1),
            "stale": bool(pose and pose.get("fault")) or (age is not None and age > STALE_S),
            "pose_fault": (pose or {}).get("fault"),
            "pose_status": pose_words(pose, now),
        }
    return found


def report_faults(changes: dict[int, tuple[str | None, float | None]]) -> None:
    """Raise an odometry_invalid alert for each robot the gate began refusing, resolve it when it is good again."""
    close_old_connections()
    robots = Robot.objects.in_bulk(list(changes))
    for robot_id, (reason, since) in changes.items():
        robot = robots.get(robot_id)
        if robot is None:
            continue
        if reason is None:
            alerts.resolve_alert("odometry_invalid", robot, "odometry valid again")
        else:
            words = fault_words(robot.name, {"fault": reason, "fault_since": since})
            alerts.raise_alert("odometry_invalid", robot, f"{words}: its moves fail until it is good again")


async def publish_to_channels(batch: list[live.RobotPose]) -> None:
    """Send one tick of poses to the browsers and keep the latest per robot for new subscribers' snapshots."""
    layer = get_channel_layer()
    if layer is not None:
        await layer.group_send(live.POSES_GROUP, live.poses(batch))
    await sync_to_async(store_poses, thread_sensitive=False)(
        batch
    )  # not behind Django's one shared sync thread


class PoseHub:
    """Latest pose per robot, flushed as one batch per tick: bursts of odometry cost one message."""

    def __init__(
        self,
        publish: Callable[[list[live.RobotPose]], Awaitable[None]] = publish_to_channels,
        rate_hz: float = DEFAULT_RATE_HZ,
        clock: Callable[[], float] = time.time,
        report: Callable[[dict], None] = report_faults,
    ) -> None:
        if not 0 < rate_hz <= 50:
            raise ValueError(f"rate_hz: must be in (0, 50], got {rate_hz}")
        self.publish = publish
        self.report = report  # the robots whose gate began or stopped refusing: alerts, from a thread
        self.period = 1.0 / rate_hz
        self.clock = clock
        self._lock = threading.Lock()
        self._offsets: dict[int, Pose2D] = {}
        self._raw_odometry: dict[int, Pose2D] = {}
        self._latest: dict[int, live.RobotPose] = {}
        self._extras: dict[int, dict] = defaultdict(dict)  # battery (percent), rtt (ms): carried in each pose
        self._dirty: set[int] = set()
        self._gates: dict[int, PoseGate] = {}
        self._faults: dict[int, tuple[str | None, float | None]] = {}  # changes not yet reported

    def track(self, robot_id: int, start_pose=None, max_linear: float = 0.0) -> None:
        """Start (or restart) following a robot from its start pose, its odometry gated at its top speed."""
        with self._lock:
            self._offsets[robot_id] = start_offset(start_pose)
            self._gates[robot_id] = PoseGate(max_linear)

    def forget(self, robot_id: int) -> None:
        with self._lock:
            for table in (self._offsets, self._raw_odometry, self._latest, self._extras, self._gates):
                table.pop(robot_id, None)
            self._dirty.discard(robot_id)

    def subscriptions(self, robot) -> list[Subscription]:
        """What to subscribe for one robot: its bound odometry, and its amcl pose when bound."""
        self.track(robot.pk, robot.start_pose, robot.max_linear)
        bindings = {binding.action: binding for binding in robot.bindings.all() if binding.target}
        # The newest odometry each tick, held by rosbridge (queue_length 1) and sent on its timer. Not the
        # throttle alone (throttle_for, as a driven robot's link asks): that keeps the full 10 Hz on a busy machine,
        # and at 500 robots on two cores this process then read its stream slower than it came, its keepalive
        # pongs came more than 4 s late and both shards' robots were said offline (bench.cluster, 2 runs of 2);
        # the queue's timer, late with a busy robot's loop, gave it 7.6-8.8 Hz instead (bench.odometry_rate).
        throttle = int(self.period * 1000)
        subs = []
        if "odometry" in bindings:
            odom = bindings["odometry"]
            callback = self._callback(self.on_odometry, robot.pk)
            subs.append(Subscription(robot.pk, odom.target, odom.message_type, callback, throttle))
        if "pose" in bindings:
            pose = bindings["pose"]
            callback = self._callback(self.on_amcl, robot.pk)
            subs.append(Subscription(robot.pk, pose.target, pose.message_type, callback, 0))
        if "battery" in bindings:
            battery = bindings["battery"]
            callback = self._callback(self.on_battery, robot.pk)
            subs.append(
                Subscription(robot.pk, battery.target, battery.message_type, callback, BATTERY_EVERY_MS)
            )
        return subs

    @staticmethod
    def _callback(handler, robot_id: int) -> Callable[[dict], None]:
        def callback(message: dict) -> None:
            try:
                handler(robot_id, message)
            except (KeyError, TypeError, ValueError) as exc:
                log.warning("robot %s: unreadable pose message dropped (%s)", robot_id, exc)

        return callback

    def on_odometry(self, robot_id: int, message: dict) -> None:
        """Take one nav_msgs/Odometry through the robot's gate: compose with its offset, keep it as the latest;
        a refused one flags the last good pose instead."""
        now = self.clock()
        with self._lock:
            gate = self._gates.setdefault(robot_id, PoseGate(0.0))
            was = gate.fault
            try:
                reading = gate.admit(message, now)
            except InvalidOdometry:
                self._flag(robot_id, gate, was)
                return
            if was is not None:
                self._faults[robot_id] = (None, None)
            raw = self._raw_odometry[robot_id] = reading.pose
            offset = self._offsets.setdefault(robot_id, (0.0, 0.0, 0.0))
            x, y, yaw = compose(offset, raw)
            self._latest[robot_id] = live.RobotPose(
                id=robot_id, x=round(x, 3), y=round(y, 3), yaw=round(yaw, 3),
                v=round(reading.v, 3), w=round(reading.w, 3), t=now, **self._extras.get(robot_id, {}),
            )  # fmt: skip
            self._dirty.add(robot_id)

    def _flag(self, robot_id: int, gate: PoseGate, was: str | None) -> None:
        """The last good pose (or none) with the gate's reason, pushed every tick while it refuses."""
        if was is None:
            self._faults[robot_id] = (gate.fault, gate.since)
            log.warning("robot %s: odometry refused (%s)", robot_id, gate.fault)
        base = self._latest.get(robot_id) or {"id": robot_id}
        self._latest[robot_id] = {**base, "fault": gate.fault, "fault_since": gate.since}
        self._dirty.add(robot_id)

    def on_amcl(self, robot_id: int, message: dict) -> None:
        """Take an amcl pose (map frame): correct the map->odom offset so odometry lands where amcl says. While
        the robot's odometry is refused its flagged pose stands: an amcl pose must not clear the flag."""
        in_map = pose_of(message)
        with self._lock:
            raw = self._raw_odometry.get(robot_id)
            self._offsets[robot_id] = compose(in_map, inverse(raw)) if raw else in_map
            gate = self._gates.get(robot_id)
            if gate is not None and gate.fault is not None:
                return  # its odometry is refused: the flagged last good pose stands, amcl rides on that odometry
            previous = self._latest.get(robot_id, {})
            self._latest[robot_id] = live.RobotPose(
                id=robot_id, x=round(in_map[0], 3), y=round(in_map[1], 3), yaw=round(in_map[2], 3),
                v=previous.get("v", 0.0), w=previous.get("w", 0.0), t=self.clock(),
                **self._extras.get(robot_id, {}),
            )  # fmt: skip
            self._dirty.add(robot_id)

    def on_battery(self, robot_id: int, message: dict) -> None:
        """Take a sensor_msgs/BatteryState: its charge in percent rides along with the robot's poses."""
        charge = message.get("percentage")
        if isinstance(charge, bool) or not isinstance(charge, int | float) or not math.isfinite(charge):
            return  # NaN: "not measured"
        self._extra(robot_id, "battery", round(charge * 100 if charge <= 1 else charge, 1))

    def on_round_trip(self, robot_ids, seconds: float) -> None:
        """The round trip of the link to these robots' endpoint (a ping), carried with their poses in ms."""
        for robot_id in robot_ids:
            self._extra(robot_id, "rtt", round(seconds * 1000, 1))

    def _extra(self, robot_id: int, key: str, value: float) -> None:
        with self._lock:
            self._extras[robot_id][key] = value
            if robot_id in self._latest:
                self._latest[robot_id] = live.RobotPose(**{**self._latest[robot_id], key: value})
                self._dirty.add(robot_id)

    def take_batch(self) -> list[live.RobotPose]:
        """The poses that changed since the last tick (each robot once), and start a new tick."""
        with self._lock:
            batch = [self._latest[robot_id] for robot_id in sorted(self._dirty)]
            self._dirty.clear()
        return batch

    async def flush(self) -> int:
        """Publish one tick (and report the robots whose gate began or stopped refusing); return how many
        robots it carried."""
        batch = self.take_batch()
        if batch:
            try:
                await self.publish(batch)
            except Exception:  # a hiccup of Redis must not end the stream
                log.exception("pose batch of %d robots not published", len(batch))
        with self._lock:
            faults, self._faults = self._faults, {}
        if faults:
            try:
                await sync_to_async(self.report, thread_sensitive=False)(faults)
            except Exception:  # the database away: the flag still rides on the poses
                log.exception("odometry faults of %d robots not reported", len(faults))
        return len(batch)

    async def run(self, stop: asyncio.Event | None = None) -> None:
        """Flush once per tick until stopped (a steady clock, so a slow tick does not drift the rate)."""
        stop = stop or asyncio.Event()
        loop = asyncio.get_running_loop()
        next_tick = loop.time()
        while not stop.is_set():
            await self.flush()
            next_tick += self.period
            delay = next_tick - loop.time()
            if delay < 0:
                next_tick, delay = loop.time(), 0
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), timeout=delay)
        await self.flush()


async def subscribe_all(client, subs: list[Subscription]) -> None:
    """Subscribe the hub's topics on a rosbridge link (robots.rosbridge renews them after a reconnection)."""
    for sub in subs:
        await client.subscribe(
            sub.topic,
            sub.msg_type,
            sub.callback,
            throttle_rate=sub.throttle_rate,
            queue_length=sub.queue_length,
        )


async def measure_round_trips(client, robot_ids, hub: PoseHub, stop: asyncio.Event | None = None) -> None:
    """Ping the endpoint's link every ROUND_TRIP_EVERY_S and give the hub the round trip of its robots."""
    stop = stop or asyncio.Event()
    while not stop.is_set() and not client.closed:
        with contextlib.suppress(RosbridgeError):
            hub.on_round_trip(robot_ids, await client.round_trip())
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), timeout=ROUND_TRIP_EVERY_S)


_MEASURING: set[asyncio.Task] = set()  # the links process's round-trip tasks, kept until they end


async def stream_endpoint(
    url: str, subs: list[Subscription], stop: asyncio.Event, hub: PoseHub | None = None
) -> None:
    """Follow the given topics on one endpoint until stopped, on a link of its own that reconnects by itself
    (and, given the hub, measure the link's round trip for the robots it carries)."""
    client = RosbridgeClient(url, reconnect=True)
    await client.start()
    try:
        await subscribe_all(client, subs)
        if hub is not None:
            await measure_round_trips(client, sorted({sub.robot_id for sub in subs}), hub, stop)
        await stop.wait()
    finally:
        await client.close()


def link_hook(hub: PoseHub):
    """A robots.links hook: on each endpoint's link, subscribe every robot's poses for the hub.

    The robots and their subscriptions are made in one call off the loop, not on Django's one shared sync thread:
    the links process writes each endpoint's link status through that thread, with a push per robot, and at
    1,000 robots a subscription made per robot behind those writes took most of a minute (bench.cluster: the
    dashboards saw 2 of 1,000 robots, the pose store held 2)."""

    def subscriptions_of(url: str) -> tuple[list[int], list[Subscription]]:
        robots = list(Robot.objects.filter(endpoint=url).prefetch_related("bindings"))
        return [r.pk for r in robots], [sub for robot in robots for sub in hub.subscriptions(robot)]

    async def hook(client, _robots) -> None:
        robot_ids, subs = await sync_to_async(subscriptions_of, thread_sensitive=False)(client.url)
        await subscribe_all(client, subs)
        task = asyncio.get_running_loop().create_task(measure_round_trips(client, robot_ids, hub))
        _MEASURING.add(task)
        task.add_done_callback(_MEASURING.discard)

    return hook


async def follow(robots, hub: PoseHub, stop: asyncio.Event) -> None:
    """Stream the poses of these robots (bindings prefetched) until stopped: one socket per endpoint."""
    per_endpoint: dict[str, list[Subscription]] = defaultdict(list)
    for robot in robots:
        per_endpoint[robot.endpoint].extend(hub.subscriptions(robot))
    tasks = [stream_endpoint(url, subs, stop, hub) for url, subs in per_endpoint.items() if subs]
    await asyncio.gather(hub.run(stop), *tasks)
