"""Planar pose math, written once: angles, quaternions, SE(2) composition, and poses out of ROS messages.

A pose is (x, y, yaw) in metres and radians. Messages are the rosbridge JSON dicts of geometry_msgs and
nav_msgs; readers are lenient (a missing field is zero) but never guess a type: a non-number raises
ValueError or TypeError, which callers treat as a bad message from an untrusted robot; a NaN or an infinity
raises NonFinite (a ValueError) naming the field, so no such number ever becomes a pose.
"""

from __future__ import annotations

import math

Pose2D = tuple[float, float, float]
ORIGIN: Pose2D = (0.0, 0.0, 0.0)


class NonFinite(ValueError):
    """A pose or twist field is NaN or infinite; the message says which ("x is NaN")."""


def finite(name: str, value) -> float:
    """The value as a float; NonFinite naming the field when it is NaN or infinite."""
    number = float(value)
    if not math.isfinite(number):
        raise NonFinite(f"{name} is {'NaN' if math.isnan(number) else 'inf' if number > 0 else '-inf'}")
    return number


def wrap(angle: float) -> float:
    """The angle in (-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


def yaw_of(q: dict) -> float:
    """The yaw of a geometry_msgs/Quaternion dict (identity when all zero or missing)."""
    x, y, z, w = (finite(f"orientation {k}", q.get(k, 0.0) or 0.0) for k in ("x", "y", "z", "w"))
    if x == y == z == w == 0.0:
        return 0.0
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def quaternion(yaw: float) -> dict:
    """The geometry_msgs/Quaternion of a rotation about z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def pose_msg(x: float, y: float, yaw: float) -> dict:
    """A geometry_msgs/Pose dict."""
    return {"position": {"x": x, "y": y, "z": 0.0}, "orientation": quaternion(yaw)}


def compose(a: Pose2D, b: Pose2D) -> Pose2D:
    """The pose b expressed in a's parent frame (a ∘ b): e.g. map pose = start (map->odom) ∘ odometry pose."""
    ax, ay, ayaw = a
    bx, by, byaw = b
    c, s = math.cos(ayaw), math.sin(ayaw)
    return ax + c * bx - s * by, ay + s * bx + c * by, wrap(ayaw + byaw)


def inverse(a: Pose2D) -> Pose2D:
    """The inverse transform of a."""
    x, y, yaw = a
    c, s = math.cos(yaw), math.sin(yaw)
    return -c * x - s * y, s * x - c * y, wrap(-yaw)


def pose_of(msg: dict) -> Pose2D:
    """(x, y, yaw) of an Odometry or PoseWithCovarianceStamped (both carry pose.pose), a PoseStamped or a Pose.

    A message without a position is not a pose: KeyError (a robot is never put at the origin by a bad message).
    """
    pose = msg.get("pose", msg) if isinstance(msg, dict) else None
    pose = pose.get("pose", pose) if isinstance(pose, dict) else None
    position = pose.get("position") if isinstance(pose, dict) else None
    if not isinstance(position, dict) or "x" not in position or "y" not in position:
        raise KeyError("no pose.position.x/y in the message")
    return finite("x", position["x"]), finite("y", position["y"]), yaw_of(pose.get("orientation") or {})


def twist_of(msg: dict) -> tuple[float, float]:
    """(linear x, angular z) of an Odometry message; zeros when it carries no twist."""
    twist = (msg.get("twist") or {}).get("twist") or {}
    linear = (twist.get("linear") or {}).get("x", 0.0) or 0.0
    angular = (twist.get("angular") or {}).get("z", 0.0) or 0.0
    return finite("linear speed", linear), finite("angular speed", angular)


def start_offset(start_pose) -> Pose2D:
    """The map->odom offset a robot starts with: its start pose ([x, y] or [x, y, yaw]), else the origin."""
    if isinstance(start_pose, list | tuple) and len(start_pose) >= 2:
        yaw = float(start_pose[2]) if len(start_pose) > 2 else 0.0
        return float(start_pose[0]), float(start_pose[1]), yaw
    return ORIGIN


def distance(a, b) -> float:
    """The planar distance between two poses or points."""
    return math.hypot(b[0] - a[0], b[1] - a[1])
