"""Navigation for simulated robots that have a nav stack: A* planning, a path follower, and the
ROS 1 move_base / ROS 2 nav2 navigate_to_pose interfaces on top of them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

from fleetcore.geometry import wrap
from fleetcore.planning import Planner

XY_TOLERANCE = 0.15
YAW_TOLERANCE = 0.1
STUCK_SECONDS = 10.0
MAX_REPLANS = 2  # replans around other robots before a stuck goal is aborted
BACKUP_SECONDS, BACKUP_SPEED = 1.5, -0.1  # the recovery before a replan: back away at 0.1 m/s
LOCAL_COSTMAP_M = 3.0  # robots closer than this are seen (the local costmap's size)
ACTIVE, PREEMPTED, SUCCEEDED, ABORTED = 1, 2, 3, 4  # actionlib_msgs/GoalStatus


class Navigator:
    """Follow a planned path within the robot's nav limits; report the outcome through a callback."""

    def __init__(self, robot, planner: Planner) -> None:
        self.robot = robot
        self.planner = planner
        self.path: list[tuple[float, float]] = []
        self.goal: tuple[float, float, float | None] | None = None
        self.on_done: Callable[[int, str], None] | None = None
        self.progress = (math.inf, 0.0)
        self.replans = 0
        self.backing_until = -1.0
        self.max_vel_x = (
            robot.profile.nav_speed
        )  # the local planner's top speed (dynamic_reconfigure sets it)
        self.speed_cap: float | None = None  # m/s: nav2's speed limit (SpeedLimit), None: no limit

    @property
    def max_speed(self) -> float:
        """The top speed the planner drives at now: its max_vel_x, or the speed limit if lower."""
        top = self.max_vel_x if self.speed_cap is None else min(self.max_vel_x, self.speed_cap)
        return max(0.0, top)

    @property
    def active(self) -> bool:
        return self.goal is not None

    def start(self, x: float, y: float, yaw: float | None, on_done: Callable[[int, str], None]) -> bool:
        """Plan to (x, y[, yaw]) and start following; False (and ABORTED reported) if no plan."""
        self.stop(PREEMPTED, "preempted by a new goal")
        rx, ry, _ = self.robot.pose()
        path = self.planner.plan((rx, ry), (x, y))
        if path is None:
            on_done(ABORTED, "Failed to find a valid plan")
            return False
        self.goal, self.path, self.on_done = (x, y, yaw), path, on_done
        self.replans = 0
        self.progress = (math.inf, self.robot.physics.time)
        return True

    def stop(self, status: int, text: str) -> None:
        """End the current goal (if any) with a status and stop the base."""
        if self.goal is None:
            return
        done, self.goal, self.path, self.on_done = self.on_done, None, [], None
        self.robot.drive(0.0, 0.0)
        if done:
            done(status, text)

    def remaining(self) -> float:
        if not self.goal:
            return 0.0
        x, y, _ = self.robot.pose()
        pts = [(x, y), *self.path]
        return sum(math.dist(a, b) for a, b in itertools.pairwise(pts))

    def tick(self) -> None:
        """Compute and send one velocity command (called at the controller frequency)."""
        if self.goal is None:
            return
        if self.robot.physics.time < self.backing_until:  # recovery: back away from what blocks us
            self.robot.drive(BACKUP_SPEED, 0.0)
            return
        x, y, yaw = self.robot.pose()
        p = self.robot.profile
        while len(self.path) > 1 and math.dist((x, y), self.path[0]) < 0.25:
            self.path.pop(0)
        tx, ty = self.path[0]
        dist = math.dist((x, y), (tx, ty))
        if len(self.path) == 1 and dist < XY_TOLERANCE:
            self._align(yaw)
            return
        self._check_stuck(dist + len(self.path))
        err = wrap(math.atan2(ty - y, tx - x) - yaw)
        w = max(-p.nav_turn, min(p.nav_turn, 2.0 * err))
        if abs(err) > 0.6:
            self.robot.drive(0.0, w)
            return
        v = min(self.max_speed, 0.8 * dist + 0.05) * math.cos(err)
        self.robot.drive(v, w)

    def _align(self, yaw: float) -> None:
        target = self.goal[2]
        if target is None or abs(wrap(target - yaw)) < YAW_TOLERANCE:
            self.stop(SUCCEEDED, "Goal reached.")
            return
        turn = self.robot.profile.nav_turn
        self.robot.drive(0.0, max(-turn, min(turn, 1.5 * wrap(target - yaw))))

    def _check_stuck(self, measure: float) -> None:
        best, since = self.progress
        now = self.robot.physics.time
        if measure < best - 0.05:
            self.progress = (measure, now)
        elif now - since > STUCK_SECONDS:
            if self.replans < MAX_REPLANS and self._replan_around_robots():
                self.replans += 1
                self.progress = (math.inf, now + BACKUP_SECONDS)
                self.backing_until = (
                    now + BACKUP_SECONDS
                )  # move_base's recovery: back up, then follow the new plan
                return
            self.stop(ABORTED, "Robot is stuck: no progress")

    def _replan_around_robots(self) -> bool:
        """Plan again with the other robots as obstacles, as move_base's costmap would see them by laser."""
        x, y, _ = self.robot.pose()
        others = [
            (ox, oy, body.profile.inscribed_radius)
            for name, body in self.robot.physics.robots.items()
            if name != self.robot.body.name
            for ox, oy, _ in [body.pose()]
            if math.dist((x, y), (ox, oy)) < LOCAL_COSTMAP_M
        ]
        path = self.planner.plan((x, y), self.goal[:2], avoid=others) if others else None
        if path is None:
            return False
        self.path = path
        return True
