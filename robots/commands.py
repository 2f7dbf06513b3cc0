"""How to command one robot: the one place that reads its move, navigate and dock bindings.

Everything that publishes to a robot (the executor's RobotLink, the STOP button and typed stops, teleop, the
watchdog's zero, the zero owed on reconnect) takes a CommandSurface and publishes what it returns; none of them
looks at bindings or message types itself. A surface is a frozen value (no database, no connection), so a
process can keep one per robot and use it from any thread or event loop.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from fleetcore import motion

NAV_MOVE_BASE, NAV_NAV2, NAV_SIMPLE = "move_base", "nav2", "simple"
TWIST = "geometry_msgs/Twist"

Publish = tuple[str, dict, str]  # (topic, message, message type): one rosbridge publish


class NoMoveTopic(RuntimeError):
    """The robot has no move topic bound, so it cannot be driven (nor stopped by a zero)."""


def navigation_kind(message_type: str, target: str) -> str | None:
    """How a navigate binding takes goals: move_base action, nav2 action, or a PoseStamped topic."""
    if not target:
        return None
    if "NavigateToPose" in message_type:
        return NAV_NAV2
    if "MoveBase" in message_type or target.rstrip("/").endswith("move_base"):
        return NAV_MOVE_BASE
    if message_type.endswith("PoseStamped"):
        return NAV_SIMPLE
    return None


def action_namespace(target: str) -> str:
    """The action's name from a bound target such as /move_base/goal or /navigate_to_pose/_action/send_goal."""
    for suffix in (
        "/_action/send_goal",
        "/_action/feedback",
        "/_action/status",
        "/goal",
        "/status",
        "/result",
    ):
        if target.endswith(suffix):
            return target[: -len(suffix)]
    return target.rstrip("/")


@dataclass(frozen=True)
class CommandSurface:
    robot_id: int
    name: str
    endpoint: str
    ros_version: int
    move_topic: str = ""
    move_type: str = TWIST
    nav_kind: str | None = None
    nav_target: str = ""
    nav_type: str = ""
    dock_target: str = ""
    dock_type: str = ""

    @classmethod
    def of(cls, robot, bindings=None) -> CommandSurface:
        """The surface of a Robot row, from its bindings (prefetched ones are used as they are)."""
        bound = {
            b.action: b for b in (bindings if bindings is not None else robot.bindings.all()) if b.target
        }
        move, navigate, dock = bound.get("move"), bound.get("navigate"), bound.get("dock")
        return cls(
            robot_id=robot.pk,
            name=robot.name,
            endpoint=robot.endpoint,
            ros_version=robot.ros_version,
            move_topic=move.target if move else "",
            move_type=(move.message_type if move else "") or TWIST,
            nav_kind=navigation_kind(navigate.message_type or "", navigate.target) if navigate else None,
            nav_target=navigate.target if navigate else "",
            nav_type=navigate.message_type if navigate else "",
            dock_target=dock.target if dock else "",
            dock_type=(dock.message_type if dock else "") or "irobot_create_msgs/action/Dock",
        )

    # ----- velocity -----
    @property
    def can_move(self) -> bool:
        return bool(self.move_topic)

    def velocity(self, v: float, w: float, t: float | None = None) -> Publish:
        """A velocity command on the robot's move topic, in its message type (Twist or TwistStamped)."""
        if not self.move_topic:
            raise NoMoveTopic(f"{self.name}: no move topic is bound; choose one on its registration page")
        now = time.time() if t is None else t
        return (
            self.move_topic,
            motion.velocity_message(v, w, self.move_type, self.ros_version, now),
            self.move_type,
        )

    def zero(self, t: float | None = None) -> list[Publish]:
        """What stops the robot now: a zero velocity, and a cancel of every move_base goal when it has one."""
        now = time.time() if t is None else t
        out = [self.velocity(0.0, 0.0, now)]
        if self.nav_kind == NAV_MOVE_BASE:
            out.append(self.cancel_move_base("", now))
        return out

    # ----- navigation -----
    @property
    def nav_namespace(self) -> str:
        return action_namespace(self.nav_target)

    def cancel_move_base(self, goal_id: str, t: float | None = None) -> Publish:
        """Cancel one move_base goal ("" cancels all)."""
        now = time.time() if t is None else t
        return f"{self.nav_namespace}/cancel", motion.goal_id(goal_id, now), "actionlib_msgs/GoalID"

    def move_base_goal(self, x: float, y: float, yaw: float, goal_id: str, t: float) -> Publish:
        message = motion.move_base_goal(x, y, yaw, goal_id, t)
        return f"{self.nav_namespace}/goal", message, "move_base_msgs/MoveBaseActionGoal"

    def simple_goal(self, x: float, y: float, yaw: float, t: float) -> Publish:
        return self.nav_target, motion.pose_stamped(x, y, yaw, t, self.ros_version), self.nav_type

    # ----- docking -----
    @property
    def can_dock(self) -> bool:
        """Whether a docking action server is bound (a ROS 2 action such as the Create 3's dock)."""
        return bool(self.dock_target) and self.ros_version == 2

    @property
    def dock_namespace(self) -> str:
        return action_namespace(self.dock_target)


def surfaces(robots) -> dict[int, CommandSurface]:
    """{robot id: surface} for Robot rows (prefetch their bindings: one query for all)."""
    return {robot.pk: CommandSurface.of(robot) for robot in robots}
