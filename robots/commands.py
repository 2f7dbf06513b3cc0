"""How to command one robot: the one place that reads its move, navigate and dock bindings.

Everything that publishes to a robot (the executor's RobotLink, the STOP button and typed stops, teleop, the
watchdog's zero, the zero owed on reconnect) takes a CommandSurface and publishes what it returns; none of them
looks at bindings or message types itself. A surface is a frozen value (no database, no connection), so a
process can keep one per robot and use it from any thread or event loop.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass
from typing import NamedTuple

from django.db.models import Count, Max, Prefetch

from fleetcore import motion
from robots.models import Binding, Robot

log = logging.getLogger(__name__)

NAV_MOVE_BASE, NAV_NAV2, NAV_SIMPLE = "move_base", "nav2", "simple"
TWIST = "geometry_msgs/Twist"
SPEED_LIMIT_TYPE = "nav2_msgs/msg/SpeedLimit"
CALL_TIMEOUT = 2.0  # s a stop's or a speed limit's service call may take

Publish = tuple[str, dict, str]  # (topic, message, message type): one rosbridge publish


class Call(NamedTuple):
    """One rosbridge call_service: a ROS 2 action's cancel_goal, a local planner's reconfigure."""

    service: str
    args: dict


Command = Publish | Call


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
    speed_target: str = ""  # nav2's speed_limit topic, or move_base's local planner's set_parameters service
    speed_kind: str = ""  # "topic" or "service"

    @classmethod
    def of(cls, robot, bindings=None) -> CommandSurface:
        """The surface of a Robot row, from its bindings (prefetched ones are used as they are)."""
        bound = {
            b.action: b for b in (bindings if bindings is not None else robot.bindings.all()) if b.target
        }
        move, navigate, dock = bound.get("move"), bound.get("navigate"), bound.get("dock")
        speed = bound.get("speed_limit")
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
            speed_target=speed.target if speed else "",
            speed_kind=speed.kind if speed else "",
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

    def zero(self, t: float | None = None, here: tuple | None = None) -> list[Command]:
        """What stops the robot now: a zero velocity, then a cancel of every goal of its navigation stack, whoever
        sent it (move_base: an empty GoalID on its cancel topic; nav2: a zero goal id to the action's
        cancel_goal service). A goal topic has no cancel: a goal at where the robot is (`here`, when known)."""
        now = time.time() if t is None else t
        out: list[Command] = [self.velocity(0.0, 0.0, now)]
        if self.nav_kind == NAV_MOVE_BASE:
            out.append(self.cancel_move_base("", now))
        elif self.nav_kind == NAV_NAV2:
            out.append(Call(f"{self.nav_namespace}/_action/cancel_goal", motion.cancel_all_goals()))
        elif self.nav_kind == NAV_SIMPLE and here is not None:
            out.append(self.simple_goal(here[0], here[1], here[2], now))
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

    # ----- speed -----
    @property
    def can_limit_speed(self) -> bool:
        """Whether its navigation stack takes a speed limit: nav2's SpeedLimit topic, move_base's reconfigure."""
        return bool(self.speed_target) and self.nav_kind in (NAV_NAV2, NAV_MOVE_BASE)

    def speed_limit(self, share: float | None, top: float | None = None, t: float | None = None) -> Command:
        """Drive the navigation stack at `share` of its own top speed (None: its own top speed again).

        nav2: a SpeedLimit in percent. move_base: the local planner's max_vel_x set to share x `top`, the value it
        had (read with read_speed; set back with share None)."""
        if self.speed_kind == "service":
            if top is None:
                raise ValueError(f"{self.name}: its planner's top speed is not known")
            return Call(self.speed_target, motion.reconfigure({"max_vel_x": top * (share or 1.0)}))
        now = time.time() if t is None else t
        percent = None if share is None or share >= 1.0 else round(100.0 * share, 2)
        return self.speed_target, motion.speed_limit(percent, now), SPEED_LIMIT_TYPE

    def read_speed(self) -> Call | None:
        """The call that reads the local planner's configuration (move_base); None where nothing needs reading."""
        return Call(self.speed_target, motion.reconfigure({})) if self.speed_kind == "service" else None

    # ----- docking -----
    @property
    def can_dock(self) -> bool:
        """Whether a docking action server is bound (a ROS 2 action such as the Create 3's dock)."""
        return bool(self.dock_target) and self.ros_version == 2

    @property
    def dock_namespace(self) -> str:
        return action_namespace(self.dock_target)


_pending: set[asyncio.Task] = set()  # calls sent on a stop's way, not waited for


async def send(client, commands: list[Command], wait: bool = False) -> list:
    """Send a surface's commands on an async rosbridge client, in order; a call's answer is waited for only with
    `wait` (a stop's cancel is not: the zero went first, the cancel's answer holds no other robot's stop)."""
    replies = []
    for item in commands:
        if isinstance(item, Call):
            if wait:
                replies.append(await client.call_service(item.service, item.args, CALL_TIMEOUT))
                continue
            task = asyncio.ensure_future(client.call_service(item.service, item.args, CALL_TIMEOUT))
            _pending.add(task)
            task.add_done_callback(_called)
        else:
            await client.publish(*item)
    return replies


def _called(task: asyncio.Task) -> None:
    _pending.discard(task)
    if not task.cancelled() and task.exception() is not None:
        log.warning("a stop's service call failed: %s", task.exception())


ROW_FIELDS = ("id", "name", "endpoint", "ros_version")  # what CommandSurface.of reads of a robot
BINDING_FIELDS = ("id", "robot_id", "action", "target", "kind", "message_type")  # and of each of its bindings


def surface_rows(robots, *more: str):
    """These Robot rows with only the columns their command surfaces read (and `more`), their bindings
    prefetched alike, unordered: a stop's targets or a press's check reads no JSON column (a robot's footprint
    and description, a binding's candidates), which was most of the time of a fleet's first teleop presses."""
    bindings = Binding.objects.only(*BINDING_FIELDS).order_by()
    return robots.only(*ROW_FIELDS, *more).prefetch_related(Prefetch("bindings", queryset=bindings))


def marked_rows(robots, *more: str):
    """These Robot rows with the columns of `more` and each one's surface mark: (its updated_at, its bindings'
    count and latest updated_at), which changes whenever anything CommandSurface.of reads of it may have (a
    surface's fields are written by save() or registration's bulk_update, both stamping updated_at; as
    robots.links.targets_mark, per robot). One query, no binding read: see kept_surfaces."""
    return (
        robots.only(*ROW_FIELDS, "updated_at", *more)
        .annotate(bindings_n=Count("bindings"), bindings_at=Max("bindings__updated_at"))
        .order_by()
    )


# robot id -> (its mark, its surface) as this process read them
_KEPT: dict[int, tuple[tuple, CommandSurface]] = {}


def kept_surfaces(rows) -> dict[int, CommandSurface]:
    """{robot id: surface} for rows of marked_rows: the surface this process read before while the robot's mark is
    the same, read again (its bindings, one query for all) for the others. A teleop press's checks run for every
    robot of a fleet pressed anew (a button released for half a second is pressed anew), and reading 1,000 robots'
    bindings each time was most of a web process's time (docs/scale.md)."""
    rows = list(rows)
    out, stale = {}, []
    for robot in rows:
        mark = (robot.updated_at, robot.bindings_n, robot.bindings_at)
        kept = _KEPT.get(robot.pk)
        if kept is not None and kept[0] == mark:
            out[robot.pk] = kept[1]
        else:
            stale.append((robot.pk, mark))
    if stale:
        marks = dict(stale)
        for robot in surface_rows(Robot.objects.filter(pk__in=list(marks))):
            out[robot.pk] = surface = CommandSurface.of(robot)
            _KEPT[robot.pk] = (marks[robot.pk], surface)
    return out


def surfaces(robots) -> dict[int, CommandSurface]:
    """{robot id: surface} for Robot rows (prefetch their bindings: one query for all)."""
    return {robot.pk: CommandSurface.of(robot) for robot in robots}
