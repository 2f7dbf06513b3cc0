"""Motion without a navigation stack, and the ROS messages that carry commands (plain: no Django).

The move-to-goal controller follows the paper's Figure 7: turn towards the goal, drive, correct the heading from
odometry as it goes, and stop within a tolerance. Tasks: rotate(n) turns on the spot n times; clean drives a
small coverage pattern around the location. A robot's map pose is its odometry composed with its start pose
(or amcl_pose when the robot has one). Each controller drives within the limits it is given: a step's pace
(`fleetcore.speed.Pace.limits`), not the robot's own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fleetcore.geometry import quaternion, wrap
from fleetcore.speed import Limits
from fleetcore.steps import parse_task

TOLERANCE = 0.1  # metres: arrived when this close to the goal
TURN_FIRST = 0.5  # rad: turn on the spot while the heading error is larger than this
K_ANGULAR, K_LINEAR = 2.5, 1.2
CLEAN_SIZE, CLEAN_LANES = 0.6, 3  # metres square, back-and-forth lanes


@dataclass(frozen=True)
class Command:
    """One velocity command; done means the controller has reached its goal (and the command is zero)."""

    v: float
    w: float
    done: bool = False


STOP = Command(0.0, 0.0, True)
HOLD = Command(0.0, 0.0)  # brake and look again at the next odometry: not done yet


@dataclass
class Approach:
    """How a relative motion (turn or drive by an amount) closes on its goal, from what is left of it and how far
    the robot went since the last command.

    A robot does not stop when told: it brakes within acceleration limits the portal does not know, and under
    load the next command may come late. Said only from where it is, a TurtleBot told to turn 90 degrees was
    stopped at 89.5 still turning at 1.2 rad/s and came to rest at 103 (bench.cluster, 100 robots). So it looks
    HORIZON commands ahead at the pace it goes (a zero, HOLD, once the goal is that near or behind: it coasts
    in, or is corrected back once it has slowed), and it is done (STOP) only within the tolerance and resting
    (moving less than a third of the tolerance between two commands); past it, it is corrected at half the
    speeds, halved again at each crossing. Having crossed the goal CROSSINGS times, it ends as soon as it rests,
    wherever that is (late commands can make a correction
    overshoot for ever; the step's words then say how far off it came to rest)."""

    tolerance: float
    crossings: int = 0
    _side: float = 0.0  # which side of the goal it was last seen on, out of the tolerance (0: not yet)

    HORIZON = 3
    CROSSINGS = 3

    @property
    def pace(self) -> float:
        """The share of its speeds a correction goes at: halved at each crossing (a late command at the slowest
        speed carried a TurtleBot's correction 3.5 degrees past)."""
        return 0.5**self.crossings

    def next(self, remaining: float, step: float) -> Command | float:
        """STOP, HOLD, or the amount to command on (signed as `remaining`)."""
        if abs(remaining) > self.tolerance:
            side = math.copysign(1.0, remaining)
            self.crossings += self._side not in (0.0, side)
            self._side = side
        if abs(remaining) <= self.tolerance or self.crossings >= self.CROSSINGS:
            return STOP if abs(step) <= self.tolerance / 3 else HOLD
        ahead = remaining - self.HORIZON * step
        if abs(ahead) <= self.tolerance or ahead * remaining < 0:
            return HOLD
        return ahead


def clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


@dataclass
class GoToGoal:
    """Figure 7: turn towards the goal, then drive while correcting the heading; stop within tolerance."""

    goal: tuple[float, float]
    limits: Limits
    tolerance: float = TOLERANCE

    def command(self, pose: tuple[float, float, float]) -> Command:
        x, y, yaw = pose
        dx, dy = self.goal[0] - x, self.goal[1] - y
        distance = math.hypot(dx, dy)
        if distance < self.tolerance:
            return STOP
        error = wrap(math.atan2(dy, dx) - yaw)
        w_max, v_max = self.limits.angular, self.limits.linear
        w = clamp(K_ANGULAR * error, w_max)
        if abs(error) > TURN_FIRST:
            return Command(0.0, _at_least(w, 0.15 * w_max))
        v = min(v_max, max(K_LINEAR * distance, 0.25 * v_max)) * math.cos(error)
        return Command(v, w)


def _at_least(w: float, minimum: float) -> float:
    """Keep a turn command above the speed at which a real base stalls."""
    return math.copysign(max(abs(w), minimum), w)


@dataclass
class Rotate:
    """Turn on the spot n full turns, counting the yaw actually turned (from odometry)."""

    turns: float
    limits: Limits
    turned: float = 0.0
    _last: float | None = None

    def command(self, pose: tuple[float, float, float]) -> Command:
        yaw = pose[2]
        if self._last is not None:
            self.turned += abs(wrap(yaw - self._last))
        self._last = yaw
        remaining = 2 * math.pi * self.turns - self.turned
        if remaining <= 0.05:
            return STOP
        w_max = self.limits.angular
        return Command(0.0, max(min(w_max, K_ANGULAR * remaining), 0.2 * w_max))


@dataclass
class Straight:
    """Drive straight by a distance along the heading it starts with (back when negative), holding that heading."""

    distance: float
    limits: Limits
    tolerance: float = 0.02
    start: tuple[float, float, float] | None = None
    _along: float = 0.0  # how far along it was at the last command

    def __post_init__(self) -> None:
        self._approach = Approach(self.tolerance)

    def command(self, pose: tuple[float, float, float]) -> Command:
        if self.start is None:
            self.start = pose
        x0, y0, yaw0 = self.start
        sign = 1.0 if self.distance >= 0 else -1.0
        along = ((pose[0] - x0) * math.cos(yaw0) + (pose[1] - y0) * math.sin(yaw0)) * sign
        step, self._along = along - self._along, along
        how = self._approach.next(abs(self.distance) - along, step)
        if isinstance(how, Command):
            return how
        v_max, w_max = self.limits.linear * self._approach.pace, self.limits.angular
        v = math.copysign(min(v_max, max(K_LINEAR * abs(how), 0.25 * v_max)), how)  # back, past the goal
        return Command(sign * v, clamp(K_ANGULAR * wrap(yaw0 - pose[2]), w_max))

    def done(self, pose: tuple[float, float, float]) -> float:
        """The distance driven so far along the start heading (negative: back), at this pose."""
        if self.start is None:
            return 0.0
        x0, y0, yaw0 = self.start
        return (pose[0] - x0) * math.cos(yaw0) + (pose[1] - y0) * math.sin(yaw0)


@dataclass
class TurnBy:
    """Turn on the spot by an angle (radians; anticlockwise when positive), counting the yaw actually turned."""

    angle: float
    limits: Limits
    tolerance: float = 0.03
    turned: float = 0.0
    _last: float | None = None

    def __post_init__(self) -> None:
        self._approach = Approach(self.tolerance)

    def command(self, pose: tuple[float, float, float]) -> Command:
        before = self.turned
        how = self._approach.next(self.angle - self.done(pose), self.turned - before)
        if isinstance(how, Command):
            return how
        w_max = self.limits.angular * self._approach.pace
        return Command(0.0, _at_least(clamp(K_ANGULAR * how, w_max), 0.15 * w_max))

    def done(self, pose: tuple[float, float, float]) -> float:
        """The yaw turned so far (radians), counting this pose (the one it came to rest at)."""
        if self._last is not None:
            self.turned += wrap(pose[2] - self._last)
        self._last = pose[2]
        return self.turned


@dataclass
class Face:
    """Turn on the spot to a heading (a goal given with one, e.g. dragged on the map), the short way round."""

    yaw: float
    limits: Limits
    tolerance: float = 0.05  # rad

    def command(self, pose: tuple[float, float, float]) -> Command:
        error = wrap(self.yaw - pose[2])
        if abs(error) <= self.tolerance:
            return STOP
        w_max = self.limits.angular
        return Command(0.0, math.copysign(max(min(w_max, K_ANGULAR * abs(error)), 0.2 * w_max), error))


def coverage_waypoints(
    center: tuple[float, float], size: float = CLEAN_SIZE, lanes: int = CLEAN_LANES
) -> list[tuple[float, float]]:
    """A back-and-forth (boustrophedon) pattern over a size x size square centred on the location."""
    if lanes < 2 or size <= 0:
        raise ValueError("a coverage pattern needs at least two lanes and a positive size")
    cx, cy = center
    half = size / 2
    points = []
    for i in range(lanes):
        y = cy - half + i * size / (lanes - 1)
        xs = (cx - half, cx + half) if i % 2 == 0 else (cx + half, cx - half)
        points += [(xs[0], y), (xs[1], y)]
    return [*points, center]


@dataclass
class Clean:
    """Drive the coverage pattern around a location, one GoToGoal leg after another."""

    center: tuple[float, float]
    limits: Limits
    legs: list[tuple[float, float]] = field(default_factory=list)

    def __post_init__(self):
        self.legs = self.legs or coverage_waypoints(self.center)

    def command(self, pose: tuple[float, float, float]) -> Command:
        while self.legs:
            command = GoToGoal(self.legs[0], self.limits, tolerance=0.12).command(pose)
            if not command.done:
                return command
            self.legs.pop(0)
        return STOP


def task_controller(task: str, pose, limits: Limits):
    """The controller for a task started at this pose."""
    name, count = parse_task(task)
    if name == "rotate":
        return Rotate(count, limits)
    return Clean((pose[0], pose[1]), limits)


# ----- messages: how commands and goals look on the wire, per ROS version and message type -----

# actionlib_msgs/GoalStatus (ROS 1) and action_msgs/GoalStatus (ROS 2) -> our outcome words.
ROS1_GOAL_STATUS = {
    0: "active", 1: "active", 6: "active", 7: "active",  # pending, active, preempting, recalling
    2: "cancelled", 8: "cancelled",  # preempted, recalled
    3: "succeeded",
    4: "failed", 5: "failed", 9: "failed",  # aborted, rejected, lost
}  # fmt: skip
ROS2_GOAL_STATUS = {
    0: "failed",
    1: "active",
    2: "active",
    3: "active",
    4: "succeeded",
    5: "cancelled",
    6: "failed",
}


def stamp(t: float, ros_version: int) -> dict:
    """A builtin time in the ROS version's field names."""
    sec = int(t)
    nanos = int((t - sec) * 1e9)
    return {"secs": sec, "nsecs": nanos} if ros_version == 1 else {"sec": sec, "nanosec": nanos}


def stamp_of(msg: dict) -> float | None:
    """A message's header stamp in seconds, in either ROS version's field names; None when missing or
    malformed (robots are untrusted input)."""
    head = msg.get("header") if isinstance(msg, dict) else None
    stamp_field = head.get("stamp") if isinstance(head, dict) else None
    if not isinstance(stamp_field, dict):
        return None
    sec = stamp_field.get("secs", stamp_field.get("sec"))
    nanos = stamp_field.get("nsecs", stamp_field.get("nanosec", 0))
    if not isinstance(sec, int | float) or not isinstance(nanos, int | float):
        return None
    return sec + nanos / 1e9


RATE_SPAN_S = 0.5  # s of wall time a clock rate is measured over
RATE_BOUNDS = (0.25, 16.0)  # clock rates believed: a simulator's time scale; beyond these, a stamp is wrong


class ClockRate:
    """How fast a robot's clock runs against ours, from the stamps of its messages: 1 for a real robot, the
    time scale of a simulator running faster than real time. Plans are made in wall time; a robot's speed in
    wall time is its speed times this rate. 1 until measured, and whenever stamps are missing or jump."""

    def __init__(self) -> None:
        self.rate = 1.0
        self.measured = False
        self._mark: tuple[float, float] | None = None  # (wall, stamp) the current span began at

    def update(self, wall: float, stamp_s: float | None) -> None:
        if stamp_s is None or stamp_s <= 0:
            return
        if self._mark is None or stamp_s < self._mark[1]:
            self._mark = (wall, stamp_s)
            return
        span = wall - self._mark[0]
        if span < RATE_SPAN_S:
            return
        rate = (stamp_s - self._mark[1]) / span
        if RATE_BOUNDS[0] <= rate <= RATE_BOUNDS[1]:
            self.rate, self.measured = rate, True
        self._mark = (wall, stamp_s)


def header(frame: str, t: float, ros_version: int) -> dict:
    head = {"stamp": stamp(t, ros_version), "frame_id": frame}
    return {"seq": 0, **head} if ros_version == 1 else head


def twist(v: float, w: float) -> dict:
    return {"linear": {"x": float(v), "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": float(w)}}


def velocity_message(v: float, w: float, message_type: str, ros_version: int, t: float = 0.0) -> dict:
    """A Twist, or a TwistStamped when the robot's move topic takes one."""
    if message_type.endswith("TwistStamped"):
        return {"header": header("base_link", t, ros_version), "twist": twist(v, w)}
    if message_type and not message_type.endswith("Twist"):
        raise ValueError(f"cannot command velocity over a {message_type!r} topic")
    return twist(v, w)


def pose_stamped(x: float, y: float, yaw: float, t: float, ros_version: int, frame: str = "map") -> dict:
    return {
        "header": header(frame, t, ros_version),
        "pose": {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": quaternion(yaw)},
    }


def move_base_goal(x: float, y: float, yaw: float, goal_id: str, t: float) -> dict:
    """A move_base_msgs/MoveBaseActionGoal with our own goal id, so status and cancel can name it."""
    return {
        "header": header("map", t, 1),
        "goal_id": {"stamp": stamp(t, 1), "id": goal_id},
        "goal": {"target_pose": pose_stamped(x, y, yaw, t, 1)},
    }


def goal_id(goal: str, t: float = 0.0) -> dict:
    """An actionlib_msgs/GoalID (cancel); an empty id cancels every goal."""
    return {"stamp": stamp(t, 1), "id": goal}


def navigate_to_pose_goal(x: float, y: float, yaw: float, t: float) -> dict:
    """The goal of nav2's navigate_to_pose action."""
    return {"pose": pose_stamped(x, y, yaw, t, 2), "behavior_tree": ""}


def cancel_all_goals() -> dict:
    """An action_msgs/srv/CancelGoal request that cancels every goal of a ROS 2 action (zero goal id and stamp),
    whoever sent them."""
    return {"goal_info": {"goal_id": {"uuid": [0] * 16}, "stamp": stamp(0.0, 2)}}


def speed_limit(percent: float | None, t: float) -> dict:
    """A nav2_msgs/msg/SpeedLimit in percent of the controller's top speed; None (0.0 on the wire) lifts it."""
    return {"header": header("", t, 2), "percentage": True, "speed_limit": float(percent or 0.0)}


def reconfigure(doubles: dict[str, float]) -> dict:
    """A dynamic_reconfigure/Reconfigure request setting these double parameters (an empty one reads them)."""
    return {"config": {"doubles": [{"name": k, "value": float(v)} for k, v in doubles.items()]}}


def reconfigured(reply: dict, name: str) -> float | None:
    """A double parameter's value in a dynamic_reconfigure/Reconfigure reply, None when absent or not a number."""
    config = reply.get("config") if isinstance(reply, dict) else None
    for item in (config or {}).get("doubles") or []:
        value = item.get("value") if isinstance(item, dict) and item.get("name") == name else None
        if (
            isinstance(value, int | float)
            and not isinstance(value, bool)
            and math.isfinite(value)
            and value > 0
        ):
            return float(value)
    return None


def move_base_outcome(status_array: dict, goal: str) -> str | None:
    """The outcome word for our goal in an actionlib_msgs/GoalStatusArray (None if it is not listed)."""
    for status in status_array.get("status_list", []):
        if status.get("goal_id", {}).get("id") == goal:
            return ROS1_GOAL_STATUS.get(int(status.get("status", 9)), "failed")
    return None
