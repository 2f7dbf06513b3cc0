"""SimFleet: one world's physics loop and all its rosbridge endpoints in one asyncio loop."""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import logging
import math
import time
from collections.abc import Callable, Iterable

from fleetcore.catalog import model
from fleetcore.planning import Planner
from fleetcore.world import World, load_world
from simworker import rosapi
from simworker.docking import DockServer
from simworker.graph import Graph
from simworker.navstack import MoveBase, Nav2
from simworker.physics import DEFAULT_DT, Physics
from simworker.robot import SimRobot
from simworker.server import RosbridgeServer

log = logging.getLogger("simworker.fleet")

NAV_HZ = 10.0  # move_base controller_frequency of the TurtleBot3 configuration
SLOW_HZ = 5.0  # laser (TB3 LDS 5 Hz), actionlib status (5 Hz)
AMCL_HZ = 2.0
DOCK_STATUS_HZ = 1.0
BATTERY_HZ = 1.0
DIAGNOSTICS_HZ = 1.0  # diagnostic_updater's default period is 1 s
CAMERA_HZ = 2.0  # the synthetic camera: small frames at a low rate
STACKS = {"move_base": MoveBase, "nav2": Nav2}


@dataclasses.dataclass
class LoopStats:
    """How well the loop keeps real time: steps run, steps that started late, worst lag."""

    steps: int = 0
    late_steps: int = 0
    max_lag: float = 0.0
    resyncs: int = 0
    started: float = 0.0


class SimFleet:
    """Own a world's physics, its robots and one rosbridge server per endpoint."""

    def __init__(
        self,
        world: str | World = "paper",
        host: str = "127.0.0.1",
        port_base: int | None = None,
        extra: int = 0,
        endpoints: Iterable[str] | None = None,
        time_scale: float = 1.0,
        dt: float = DEFAULT_DT,
        odom_rate: float = 20.0,
        odom_noise: float = 0.0,
        keep_last_command: bool = False,
        extra_skip: int = 0,
        extra_spacing: float | None = None,
    ) -> None:
        self.world = load_world(world) if not isinstance(world, World) else world
        self.world.add_extra_robots(extra, extra_skip, extra_spacing)
        self.host = host
        self.time_scale = time_scale
        self.odom_period = 1.0 / odom_rate
        self.keep_last_command = keep_last_command  # bases without a cmd_vel timeout: drive on for ever
        self.physics = Physics(self.world.map, dt)
        self.epoch = time.time()
        self.stats = LoopStats()
        self._stop: asyncio.Event | None = None
        wanted = set(endpoints) if endpoints is not None else None
        used = {r.endpoint for r in self.world.robots}
        self.servers: dict[str, RosbridgeServer] = {}
        for ep in self.world.endpoints:
            if ep.key in used and (wanted is None or ep.key in wanted):
                port = 0 if port_base is None else port_base + ep.port_offset
                self.servers[ep.key] = RosbridgeServer(ep.key, Graph(ep.ros_version, self.clock), port)
        self.robots: dict[str, SimRobot] = {}
        self.diagnostics_turn = 0  # whose diagnostics go next (simworker.diagnostics, once a second each)
        self.stacks: list = []
        self.docks: list[DockServer] = []
        planners: dict[str, Planner] = {}
        for spec in self.world.robots:
            if spec.endpoint in self.servers:
                self._add_robot(spec, odom_noise, planners)
        for server in self.servers.values():
            rosapi.finish(server.graph)

    def _add_robot(self, spec, odom_noise: float, planners: dict[str, Planner]) -> None:
        profile = model(spec.model)
        if self.keep_last_command:
            profile = dataclasses.replace(profile, cmd_timeout=math.inf)
        body = self.physics.add_robot(spec.name, profile, spec.x, spec.y, spec.yaw)
        robot = SimRobot(
            spec, profile, body, self.physics, self.servers[spec.endpoint], self.clock, odom_noise
        )
        self.robots[spec.name] = robot
        if spec.stack:
            if profile.key not in planners:
                planners[profile.key] = Planner(self.world.map, profile.inscribed_radius)
            stack = STACKS[spec.stack](robot, planners[profile.key])
            robot.navigator = stack
            self.stacks.append(stack)
            if spec.dock is not None:  # the world allows a dock on nav2 robots only
                self.docks.append(DockServer(stack, spec.dock))

    def clock(self) -> float:
        """Return the simulated ROS time (wall time at start plus simulated seconds)."""
        return self.epoch + self.physics.time

    @property
    def urls(self) -> dict[str, str]:
        return {key: f"ws://{self.host}:{s.port}" for key, s in self.servers.items()}

    async def start(self) -> None:
        """Open every endpoint's server."""
        self._stop = asyncio.Event()
        for server in self.servers.values():
            await server.start(self.host)
        for stack in self.stacks:
            stack.publish_amcl_pose()

    async def close(self) -> None:
        for server in self.servers.values():
            await server.stop()

    def request_stop(self) -> None:
        """Ask the loop to finish (call from the loop's thread, e.g. a signal handler)."""
        if self._stop is not None:
            self._stop.set()

    async def run(self, on_ready: Callable[[SimFleet], None] | None = None) -> None:
        """Start the servers, run the physics in real time until request_stop(), then close."""
        await self.start()
        gc.collect()
        gc.freeze()  # the world's long-lived objects leave the collector's scans: shorter pauses
        try:
            if on_ready is not None:
                on_ready(self)
            await self._loop()
        finally:
            await self.close()

    async def _loop(self) -> None:
        loop = asyncio.get_running_loop()
        period = self.physics.dt / self.time_scale
        next_t = self.stats.started = loop.time()
        due = dict.fromkeys(("odom", "nav", "slow", "amcl", "dock", "battery", "diagnostics", "camera"), 0.0)
        while not self._stop.is_set():
            self.physics.step()
            self.stats.steps += 1
            self._publish(due)
            next_t += period
            delay = next_t - loop.time()
            if delay < 0:
                self.stats.late_steps += 1
                self.stats.max_lag = max(self.stats.max_lag, -delay)
                if delay < -0.5:  # too far behind to catch up: drop the backlog
                    self.stats.resyncs += 1
                    next_t = loop.time()
            await asyncio.sleep(max(delay, 0.0))

    def _publish(self, due: dict[str, float]) -> None:
        """Run the periodic publishers whose time has come (odometry 20 Hz, nav and docking 10 Hz, laser 5 Hz)."""
        t = self.physics.time
        stamp = self.clock()
        if t >= due["odom"]:
            due["odom"] += self.odom_period
            for robot in self.robots.values():
                robot.publish_odometry(stamp)
        if t >= due["nav"]:
            due["nav"] += 1.0 / NAV_HZ
            for stack in self.stacks:
                if stack.nav.active:
                    stack.tick(stamp)
            for dock in self.docks:
                if dock.active:
                    dock.tick(stamp)
        if t >= due["slow"]:
            due["slow"] += 1.0 / SLOW_HZ
            for robot in self.robots.values():
                robot.publish_scan(stamp)
            for stack in self.stacks:
                stack.slow_tick(stamp)
        if t >= due["amcl"]:
            due["amcl"] += 1.0 / AMCL_HZ
            for stack in self.stacks:
                stack.publish_amcl_pose()
        if t >= due["dock"]:
            due["dock"] += 1.0 / DOCK_STATUS_HZ
            for dock in self.docks:
                dock.publish_status(stamp)
        if t >= due["battery"]:
            due["battery"] += 1.0 / BATTERY_HZ
            for robot in self.robots.values():
                robot.publish_battery(stamp, 1.0 / BATTERY_HZ)
        self._publish_diagnostics(t, stamp, due)
        if t >= due["camera"]:
            due["camera"] += 1.0 / CAMERA_HZ
            for robot in self.robots.values():
                robot.publish_camera(stamp)

    def _publish_diagnostics(self, t: float, stamp: float, due: dict[str, float]) -> None:
        """Each robot's diagnostics once a second, the robots' turns spread over the second (real robots' nodes
        are not in step; a throttled subscriber to a shared /diagnostics would otherwise only see the first)."""
        robots = list(self.robots.values())
        while robots and t >= due["diagnostics"]:
            due["diagnostics"] += 1.0 / (DIAGNOSTICS_HZ * len(robots))
            robots[self.diagnostics_turn % len(robots)].publish_diagnostics(stamp)
            self.diagnostics_turn += 1

    def pose(self, name: str) -> tuple[float, float, float]:
        """Return a robot's ground-truth pose (call from the loop's thread)."""
        return self.robots[name].pose()
