"""Every push to browsers goes through here: typed payloads sent to Channels groups after the commit.

Groups: "fleet" (every dashboard), "robot.<pk>" (a robot's page) and "alerts" (every page's alert badge). Consumers only authenticate, join groups
and forward; the handler name in the consumer matches the payload's "type".
"""

from typing import NotRequired, TypedDict

from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.db import transaction

FLEET_GROUP = "fleet"
ALERTS_GROUP = "alerts"


def robot_group(robot_id: int) -> str:
    return f"robot.{robot_id}"


class RobotStatus(TypedDict, total=False):
    type: str  # "robot.status"
    robot: str
    id: int
    link_status: str
    state: str
    last_seen: str | None


class StateChange(TypedDict):
    type: str  # "robot.transition"
    robot: str
    id: int
    from_state: str
    to_state: str
    at: str
    reason: str
    instruction: int | None


class InstructionUpdate(TypedDict, total=False):
    type: str  # "instruction.update"
    id: int
    text: str
    status: str
    outcome: str


class AlertUpdate(TypedDict):
    type: str  # "alert.update"
    alert: dict  # alerts.service.as_dict: id, kind, severity, robot, message, count, status, who and when
    open_count: int  # alerts open now, for every page's badge


def send(group: str, payload: dict) -> None:
    """Send now (from sync code outside a transaction, or from a worker loop)."""
    layer = get_channel_layer()
    if layer is not None:
        async_to_sync(layer.group_send)(group, payload)


def send_on_commit(group: str, payload: dict) -> None:
    """Send once the current transaction commits, so browsers never see state the database lacks."""
    transaction.on_commit(lambda: send(group, payload))


def robot_status(robot) -> None:
    """A robot's link status or state changed."""
    payload = RobotStatus(
        type="robot.status",
        robot=robot.name,
        id=robot.pk,
        link_status=robot.link_status,
        state=robot.state,
        last_seen=robot.last_seen.isoformat() if robot.last_seen else None,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def transition(robot, record) -> None:
    """A stored StateTransition, pushed to the fleet and the robot's page."""
    payload = StateChange(
        type="robot.transition",
        robot=robot.name,
        id=robot.pk,
        from_state=record.from_state,
        to_state=record.to_state,
        at=record.at.isoformat(),
        reason=record.reason,
        instruction=record.instruction_id,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def instruction(instruction) -> None:
    """An instruction's status or outcome changed."""
    send_on_commit(
        FLEET_GROUP,
        InstructionUpdate(
            type="instruction.update",
            id=instruction.pk,
            text=instruction.text,
            status=instruction.status,
            outcome=instruction.outcome,
        ),
    )


def alert(alert: dict, open_count: int) -> None:
    """An alert was raised, repeated, acknowledged or resolved (every page shows a badge and a toast)."""
    send_on_commit(ALERTS_GROUP, AlertUpdate(type="alert.update", alert=alert, open_count=open_count))


# Poses travel on their own group: high-rate telemetry, one batched message per tick for the whole fleet.
POSES_GROUP = "fleet.poses"
POSE_CACHE_KEY = "fleet:pose:{id}"


class RobotPose(TypedDict):
    id: int
    x: float
    y: float
    yaw: float
    v: float  # linear speed, m/s
    w: float  # angular speed, rad/s
    t: float  # unix time of the odometry message
    battery: NotRequired[float]  # percent, from the robot's bound sensor_msgs/BatteryState, when it has one
    rtt: NotRequired[float]  # ms, the round trip of a ping on the link to the robot's endpoint


class PoseBatch(TypedDict):
    type: str  # "fleet.poses"
    poses: list[RobotPose]


class LeaseUpdate(TypedDict):
    type: str  # "lease.update"
    id: int
    robot: str
    holder: str | None
    expires_at: str | None


class GoalUpdate(TypedDict):
    type: str  # "robot.goal"
    id: int
    robot: str
    name: str | None
    x: float | None
    y: float | None


class RobotPath(TypedDict):
    type: str  # "robot.path"
    id: int
    robot: str
    path: list[list[float]] | None  # the route it has reserved, [[x, y], ...]; None: unchanged; []: none
    waiting_for: str | None  # the robot it waits for to make way, if any


class RobotScan(TypedDict):
    type: str  # "robot.scan"
    id: int
    topic: str
    scan: dict  # angle_min, angle_increment, range_min, range_max, ranges (m, rounded; null: no return)


class RobotCamera(TypedDict):
    type: str  # "robot.camera"
    id: int
    topic: str
    format: str  # sensor_msgs/CompressedImage's format: "jpeg", "png" (maybe with the encoding before it)
    data: str  # the image, base64 (as rosbridge sends uint8[])


def scan(robot_id: int, topic: str, message: dict) -> RobotScan:
    """One laser scan for a robot's page or a map's selected robot (sent by portal.feeds, on its socket)."""
    ranges = [round(r, 3) if isinstance(r, int | float) else None for r in message.get("ranges") or []]
    fields = ("angle_min", "angle_increment", "range_min", "range_max")
    return RobotScan(
        type="robot.scan",
        id=robot_id,
        topic=topic,
        scan={**{k: message.get(k) for k in fields}, "ranges": ranges},
    )


def camera(robot_id: int, topic: str, message: dict) -> RobotCamera:
    """One camera frame for a robot's page (sent by portal.feeds, on its socket)."""
    return RobotCamera(
        type="robot.camera",
        id=robot_id,
        topic=topic,
        format=str(message.get("format", "")),
        data=message.get("data", ""),
    )


class RegistrationProgress(TypedDict, total=False):
    type: str  # "registration.progress"
    endpoint: str
    stage: str  # e.g. connecting, discovering, identifying, done, failed
    message: str
    robots: list[str]
    ok: bool | None


def lease(robot, current=None) -> None:
    """A robot's control lease was taken, renewed, released or taken over (current: the lease now, or None)."""
    active = current is not None and current.active
    payload = LeaseUpdate(
        type="lease.update",
        id=robot.pk,
        robot=robot.name,
        holder=current.user.username if active else None,
        expires_at=current.expires_at.isoformat() if active else None,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def goal(robot, name: str | None, x: float | None, y: float | None) -> None:
    """A robot's current goal changed (None clears it); the map draws it."""
    payload = GoalUpdate(type="robot.goal", id=robot.pk, robot=robot.name, name=name, x=x, y=y)
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def path(robot, points, waiting_for: str | None) -> None:
    """A robot's reserved route changed (points; None leaves it as drawn), or whom it waits for; the map
    draws both. Sent at once: the executor pushes it from its loop, outside any transaction."""
    payload = RobotPath(
        type="robot.path",
        id=robot.pk,
        robot=robot.name,
        path=None if points is None else [[float(x), float(y)] for x, y in points],
        waiting_for=waiting_for,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def registration(endpoint: str, stage: str, message: str = "", robots=(), ok: bool | None = None) -> None:
    """Progress of one endpoint's registration, for the registration page."""
    send_on_commit(
        FLEET_GROUP,
        RegistrationProgress(
            type="registration.progress",
            endpoint=endpoint,
            stage=stage,
            message=message,
            robots=list(robots),
            ok=ok,
        ),
    )


def poses(batch: list[RobotPose]) -> PoseBatch:
    """The message for one tick of poses (sent by robots.poses, which owns the rate)."""
    return PoseBatch(type="fleet.poses", poses=batch)
