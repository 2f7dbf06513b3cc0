"""Headless 2D physics for the simulated fleet (pymunk), stepped at a fixed dt.

Robots are dynamic boxes driven through `velocity_func`: Chipmunk calls it after collision detection, so
the solver still corrects the commanded velocity and a robot stops at a wall instead of passing through
(see stack-notes, "pymunk trap"). Per robot per step the only Python work is that one callback, and
resting robots fall asleep so they cost nothing until the next command (or a touch) wakes them.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import pymunk
from pymunk._chipmunk import lib as _cp

from fleetcore.catalog import Laser, ModelProfile
from fleetcore.mapfile import OCCUPIED, OccupancyGrid

DEFAULT_DT = 1.0 / 50.0
WALL_CATEGORY = 0b01
ROBOT_CATEGORY = 0b10
ROBOT_COLLISION = 1  # pymunk collision_type of every robot shape: robot-robot contacts are counted


def _clamp(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


@dataclass
class Command:
    """A velocity command in the body frame, with the sim time it arrived."""

    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0
    stamp: float = -1e9


@dataclass(frozen=True)
class Contact:
    """Two robots' bodies began to touch at simulated time t (s)."""

    t: float
    a: str
    b: str


class RobotBody:
    """One robot's body: footprint, limits, the last command and the velocity actually applied."""

    def __init__(self, physics: Physics, name: str, profile: ModelProfile, group: int) -> None:
        self.physics = physics
        self.name = name
        self.profile = profile
        self.cmd = Command()
        self.vx = self.vy = self.wz = 0.0  # applied, within the acceleration limits
        self.body = pymunk.Body(
            profile.mass, pymunk.moment_for_box(profile.mass, (profile.length, profile.width))
        )
        half_l, half_w, off = profile.length / 2, profile.width / 2, profile.offset_x
        box = [
            (off - half_l, -half_w),
            (off + half_l, -half_w),
            (off + half_l, half_w),
            (off - half_l, half_w),
        ]
        self.shape = pymunk.Poly(self.body, box, radius=0.005)
        self.shape.friction = 0.2
        self.shape.filter = pymunk.ShapeFilter(group=group, categories=ROBOT_CATEGORY)
        self.shape.collision_type = ROBOT_COLLISION
        self.body.velocity_func = self._drive
        self._cp_body = self.body._body  # Chipmunk's own body, for the drive's direct calls

    def command(self, vx: float, wz: float, vy: float = 0.0) -> None:
        """Take a new velocity command (clamped to the controller's limits) and wake the body."""
        p = self.profile
        self.cmd = Command(
            _clamp(vx, p.min_v, p.max_v),
            _clamp(vy, -p.max_vy, p.max_vy),
            _clamp(wz, -p.max_w, p.max_w),
            self.physics.time,
        )
        self.body.activate()

    def _drive(self, body: pymunk.Body, gravity, damping: float, dt: float) -> None:
        """Ramp toward the command within the acceleration limits and set the body's velocity.

        Called for every awake robot at every step (50 Hz), through CFFI: the simulator's dearest line. So the
        ramp is worked out only while the velocity is not yet the command's, the clamps are written inline,
        and Chipmunk is called directly (pymunk's property setters go through a Python __setattr__: 2.0 µs
        for the two against 0.4).

        A robot at rest writes nothing while its body is at rest: Chipmunk's setters wake the body (they
        reset its idle time), and a robot that set its zero velocity every step never fell asleep (40 of 40
        awake after 3 s, 20 of them with no command). A resting body that was pushed is set back to rest."""
        p, cmd = self.profile, self.cmd
        if self.physics.time - cmd.stamp > p.cmd_timeout:  # diff_drive_controller's cmd_vel_timeout
            tx = ty = tw = 0.0
        else:
            tx, ty, tw = cmd.vx, cmd.vy, cmd.wz
        vx, vy, wz = self.vx, self.vy, self.wz
        if vx != tx or vy != ty or wz != tw:
            dv, dw = p.acc_v * dt, p.acc_w * dt
            d = tx - vx
            vx += -dv if d < -dv else dv if d > dv else d
            d = ty - vy
            vy += -dv if d < -dv else dv if d > dv else d
            d = tw - wz
            wz += -dw if d < -dw else dw if d > dw else d
            self.vx, self.vy, self.wz = vx, vy, wz
        handle = self._cp_body
        if vx or vy:
            a = _cp.cpBodyGetAngle(handle)
            c, s = math.cos(a), math.sin(a)
            _cp.cpBodySetVelocity(handle, (vx * c - vy * s, vx * s + vy * c))
        else:
            v = _cp.cpBodyGetVelocity(handle)
            if v.x or v.y:
                _cp.cpBodySetVelocity(handle, (0.0, 0.0))
        if wz or _cp.cpBodyGetAngularVelocity(handle):
            _cp.cpBodySetAngularVelocity(handle, wz)

    def pose(self) -> tuple[float, float, float]:
        """Return the ground-truth pose (x, y, yaw) of base_footprint in the map frame."""
        x, y = self.body.position
        c, s = self.body.rotation_vector
        return x, y, math.atan2(s, c)

    def twist(self) -> tuple[float, float, float]:
        """Return the measured body-frame velocity (vx, vy, wz)."""
        vx, vy = self.body.velocity
        c, s = self.body.rotation_vector
        return vx * c + vy * s, -vx * s + vy * c, self.body.angular_velocity


class Physics:
    """The world's space: static walls from the occupancy grid plus one body per robot."""

    def __init__(self, grid: OccupancyGrid, dt: float = DEFAULT_DT, seed: int = 0) -> None:
        if grid.origin[2]:
            raise ValueError("physics needs a map with origin yaw 0")
        self.dt = dt
        self.time = 0.0
        self.steps = 0
        self.rng = random.Random(seed)
        self.space = pymunk.Space()
        self.space.iterations = 6
        self.space.sleep_time_threshold = 0.5
        self.robots: dict[str, RobotBody] = {}
        self._names: dict[pymunk.Shape, str] = {}
        self.contacts: list[
            Contact
        ] = []  # every robot-robot touch, in order (tests and the bench count them)
        self.space.on_collision(ROBOT_COLLISION, ROBOT_COLLISION, begin=self._touched)
        self.wall_boxes = wall_boxes(grid)
        for x0, y0, x1, y1 in self.wall_boxes:
            shape = pymunk.Poly.create_box_bb(self.space.static_body, pymunk.BB(x0, y0, x1, y1))
            shape.friction = 0.2
            shape.filter = pymunk.ShapeFilter(categories=WALL_CATEGORY)
            self.space.add(shape)

    def add_robot(self, name: str, profile: ModelProfile, x: float, y: float, yaw: float) -> RobotBody:
        """Place a robot body at (x, y, yaw) and return it."""
        if name in self.robots:
            raise ValueError(f"robot {name!r} already in the world")
        robot = RobotBody(self, name, profile, group=len(self.robots) + 1)
        robot.body.position = (x, y)
        robot.body.angle = yaw
        self.space.add(robot.body, robot.shape)
        self.robots[name] = robot
        self._names[robot.shape] = name
        return robot

    def add_fixture(self, x: float, y: float, yaw: float, length: float, width: float) -> None:
        """Place a static box the map does not show (a dock station): robots bump into it, lasers see it."""
        c, s = math.cos(yaw), math.sin(yaw)
        hl, hw = length / 2, width / 2
        points = [
            (x + c * dx * hl - s * dy * hw, y + s * dx * hl + c * dy * hw)
            for dx, dy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
        shape = pymunk.Poly(self.space.static_body, points)
        shape.friction = 0.2
        shape.filter = pymunk.ShapeFilter(categories=WALL_CATEGORY)
        self.space.add(shape)

    def _touched(self, arbiter: pymunk.Arbiter, space, data) -> None:
        """Two robot bodies began to touch: record who and when (the collision is still solved normally)."""
        a, b = (self._names.get(shape, "?") for shape in arbiter.shapes)
        self.contacts.append(Contact(self.time, *sorted((a, b))))

    def step(self) -> None:
        """Advance the world by one fixed dt."""
        self.space.step(self.dt)
        self.time += self.dt
        self.steps += 1

    def scan(self, robot: RobotBody, laser: Laser, noise: float = 0.0) -> list[float | None]:
        """Cast the laser's rays from the robot; None where nothing is in range (null on the wire)."""
        x, y, yaw = robot.pose()
        flt = pymunk.ShapeFilter(group=robot.shape.filter.group)
        n = laser.samples
        inc = (laser.angle_max - laser.angle_min) / max(n - 1, 1)
        rmax, rmin = laser.range_max, laser.range_min
        query = self.space.segment_query_first
        ranges: list[float | None] = []
        for i in range(n):
            a = yaw + laser.angle_min + i * inc
            hit = query((x, y), (x + rmax * math.cos(a), y + rmax * math.sin(a)), 0.0, flt)
            if hit is None:
                ranges.append(None)
                continue
            r = hit.alpha * rmax + (self.rng.gauss(0.0, noise) if noise else 0.0)
            ranges.append(round(r, 4) if rmin <= r <= rmax else None)
        return ranges


def wall_boxes(grid: OccupancyGrid) -> list[tuple[float, float, float, float]]:
    """Merge occupied cells into axis-aligned boxes (row runs, then equal runs stacked upward)."""
    res, (ox, oy, _) = grid.resolution, grid.origin
    open_runs: dict[tuple[int, int], int] = {}  # (col0, col1) -> first row
    boxes = []

    def close(run: tuple[int, int], row0: int, row1: int) -> None:
        boxes.append((ox + run[0] * res, oy + row0 * res, ox + run[1] * res, oy + row1 * res))

    for row in range(grid.height + 1):
        runs = set(_runs(grid, row)) if row < grid.height else set()
        for run in [r for r in open_runs if r not in runs]:
            close(run, open_runs.pop(run), row)
        for run in runs:
            open_runs.setdefault(run, row)
    return boxes


def _runs(grid: OccupancyGrid, row: int) -> list[tuple[int, int]]:
    """Return [col0, col1) runs of occupied cells in a row."""
    data, w = grid.data, grid.width
    base = row * w
    runs, start = [], None
    for col in range(w):
        occ = data[base + col] == OCCUPIED
        if occ and start is None:
            start = col
        elif not occ and start is not None:
            runs.append((start, col))
            start = None
    if start is not None:
        runs.append((start, w))
    return runs
