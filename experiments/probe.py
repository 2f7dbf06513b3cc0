"""Measuring points on a robot: command received at its endpoint (simulator hook) and motion from odometry.

Every time is wall-clock `time.time()`, so points taken in other processes (the portal's stored timestamps) compare.
"""

import asyncio
import contextlib
import math
import time
from collections import defaultdict
from dataclasses import dataclass, field

MOVING_LINEAR = 0.01  # m/s: above this the robot has started
MOVING_ANGULAR = 0.02  # rad/s
STILL_LINEAR = 0.005  # m/s: below this (and STILL_ANGULAR) the robot has stopped
STILL_ANGULAR = 0.01

TWIST_TYPE = "geometry_msgs/Twist"
ODOM_TYPE = "nav_msgs/Odometry"


def twist(linear: float, angular: float) -> dict:
    return {"linear": {"x": linear, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": angular}}


@dataclass
class RobotLink:
    """What a benchmark needs to know about one robot: topics and limits."""

    name: str
    cmd_topic: str
    odom_topic: str
    max_linear: float
    max_angular: float
    endpoint_key: str = ""
    url: str = ""
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def cap(self, linear: float, angular: float) -> tuple[float, float]:
        """The paper's speed capped by this robot's limits."""
        return min(linear, self.max_linear), min(angular, self.max_angular)


def sim_robot_link(sim, name: str) -> RobotLink:
    """The hand-known topics of a simulated robot (what an operator typing `rostopic pub` would use)."""
    robot = sim.fleet.robots[name]
    cmd = next(t for t, p in robot.iface.cmd_inputs.items() if p == max(robot.iface.cmd_inputs.values()))
    key = robot.spec.endpoint
    return RobotLink(
        name,
        cmd,
        robot.iface.odom_topics[0][0],
        robot.profile.max_v,
        robot.profile.max_w,
        key,
        sim.urls[key],
        robot.start,
    )


class Reception:
    """Timestamps of every message the simulator's endpoint received on watched topics."""

    def __init__(self, sim) -> None:
        self.sim = sim
        self.times: dict[tuple[str, str], list[tuple[float, float, float]]] = defaultdict(list)
        self._watched: set[tuple[str, str]] = set()

    def watch(self, link: RobotLink) -> None:
        key = (link.endpoint_key, link.cmd_topic)
        if key in self._watched:
            return
        self._watched.add(key)
        graph = self.sim.fleet.servers[link.endpoint_key].graph
        self.sim.call(graph.on_topic, link.cmd_topic, lambda msg, k=key: self._record(k, msg))

    def _record(self, key: tuple[str, str], msg: dict) -> None:
        lin, ang = msg.get("linear") or {}, msg.get("angular") or {}
        self.times[key].append(
            (time.time(), float(lin.get("x", 0.0) or 0.0), float(ang.get("z", 0.0) or 0.0))
        )

    def first_after(
        self, link: RobotLink, since: float, angular: float | None = None, zero: bool = False
    ) -> float | None:
        """When the endpoint first got a command after `since` (with this angular speed, or a zero one)."""
        for t, lin, ang in self.times.get((link.endpoint_key, link.cmd_topic), []):
            if t < since:
                continue
            if zero and (lin or ang):
                continue
            if angular is not None and abs(ang - angular) > 1e-6:
                continue
            return t
        return None


@dataclass
class OdomWatch:
    """The odometry of one robot as it arrives: (time, |v|, |w|) samples and a wake-up event."""

    link: RobotLink
    samples: list[tuple[float, float, float]] = field(default_factory=list)
    event: asyncio.Event = field(default_factory=asyncio.Event)

    def on_message(self, msg: dict) -> None:
        tw = msg.get("twist", {}).get("twist", {})
        lin, ang = tw.get("linear", {}), tw.get("angular", {})
        speed = math.hypot(lin.get("x", 0.0) or 0.0, lin.get("y", 0.0) or 0.0)
        self.samples.append((time.time(), speed, abs(ang.get("z", 0.0) or 0.0)))
        del self.samples[:-200]
        self.event.set()

    async def wait_for(self, predicate, since: float, timeout: float) -> float | None:
        """The time of the first sample after `since` that satisfies predicate(v, w); None on timeout."""
        deadline = time.time() + timeout
        while True:
            hit = next((t for t, v, w in self.samples if t >= since and predicate(v, w)), None)
            if hit is not None or time.time() >= deadline:
                return hit
            self.event.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.event.wait(), max(0.001, deadline - time.time()))

    async def moving(self, since: float, timeout: float = 5.0) -> float | None:
        return await self.wait_for(lambda v, w: v > MOVING_LINEAR or w > MOVING_ANGULAR, since, timeout)

    async def still(self, since: float, timeout: float = 5.0) -> float | None:
        return await self.wait_for(lambda v, w: v < STILL_LINEAR and w < STILL_ANGULAR, since, timeout)


async def watch_odometry(client, link: RobotLink) -> OdomWatch:
    watch = OdomWatch(link)
    await client.subscribe(link.odom_topic, ODOM_TYPE, watch.on_message)
    return watch
