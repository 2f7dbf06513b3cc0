"""Every push to browsers goes through here: typed payloads sent to Channels groups after the commit.

Groups: "fleet" (every dashboard) and "robot.<pk>" (a robot's page). Consumers only authenticate, join groups
and forward; the handler name in the consumer matches the payload's "type".
"""

from typing import TypedDict

from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.db import transaction

FLEET_GROUP = "fleet"


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


# Poses travel on their own group: high-rate telemetry, one batched message per tick for the whole fleet.
POSES_GROUP = "robots.poses"
POSE_CACHE_KEY = "fleet:pose:{id}"


class RobotPose(TypedDict):
    id: int
    x: float
    y: float
    yaw: float
    v: float  # linear speed, m/s
    w: float  # angular speed, rad/s
    t: float  # unix time of the odometry message


class PoseBatch(TypedDict):
    type: str  # "robots.poses"
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


class RegistrationProgress(TypedDict, total=False):
    type: str  # "registration.progress"
    endpoint: str
    stage: str  # e.g. connecting, discovering, identifying, done, failed
    message: str
    robots: list[str]
    ok: bool | None


def lease(robot) -> None:
    """A robot's control lease was taken, renewed, released or taken over."""
    from access.models import ControlLease

    current = ControlLease.objects.filter(robot=robot).select_related("user").first()
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
    return PoseBatch(type="robots.poses", poses=batch)


def _robot_row(robot, holders: dict, current: dict, goals: dict, cached: dict) -> dict:
    """One robot as the browser draws it."""
    return {
        "id": robot.pk,
        "name": robot.name,
        "model": robot.model,
        "drive": robot.drive,
        "state": robot.state,
        "link_status": robot.link_status,
        "footprint": robot.footprint,
        "max_linear": robot.max_linear,
        "max_angular": robot.max_angular,
        "start_pose": robot.start_pose,
        "holder": holders.get(robot.pk),
        "instruction": current.get(robot.pk),
        "goal": goals.get(robot.pk),
        "pose": cached.get(POSE_CACHE_KEY.format(id=robot.pk)),
    }


def current_work(robot_ids, running_only: bool = False) -> tuple[dict, dict]:
    """Per robot: the instruction it is working on ({id, text, status}) and its goal ({name, x, y})."""
    from execution.models import Execution

    current, goals = {}, {}
    active = ("running",) if running_only else ("running", "queued")
    rows = Execution.objects.filter(robot_id__in=robot_ids, status__in=active).select_related("instruction")
    for execution in rows.order_by("created_at"):
        if execution.robot_id in current:
            continue
        current[execution.robot_id] = {
            "id": execution.instruction_id,
            "text": execution.instruction.text,
            "status": execution.status,
        }
        steps = execution.steps or []
        step = steps[min(execution.step_index, len(steps) - 1)] if steps else {}
        destination = step.get("destination") if isinstance(step, dict) else None
        if destination and destination.get("x") is not None:
            goals[execution.robot_id] = {
                "name": destination.get("name"),
                "x": destination["x"],
                "y": destination["y"],
            }
    return current, goals


def robot_rows(robots) -> list[dict]:
    """The robots with their holders, current instructions, goals and last poses, in few queries."""
    from django.core.cache import cache
    from django.utils import timezone

    from access.models import ControlLease

    robots = list(robots)
    ids = [robot.pk for robot in robots]
    holders = dict(
        ControlLease.objects.filter(robot_id__in=ids, expires_at__gt=timezone.now()).values_list(
            "robot_id", "user__username"
        )
    )
    current, goals = current_work(ids)
    try:
        cached = cache.get_many([POSE_CACHE_KEY.format(id=pk) for pk in ids])
    except Exception:  # a missing cache only costs the first tick of poses
        cached = {}
    return [_robot_row(robot, holders, current, goals, cached) for robot in robots]


def _instruction_row(instruction) -> dict:
    return {
        "id": instruction.pk,
        "text": instruction.text,
        "status": instruction.status,
        "type": instruction.type,
        "outcome": instruction.outcome,
        "user": instruction.user.username if instruction.user else None,
    }


def fleet_snapshot() -> dict:
    """What a new dashboard subscriber sees first: every robot (lease, goal, pose) and recent instructions."""
    from execution.models import Instruction
    from robots.models import Robot

    recent = Instruction.objects.select_related("user")[:20]
    return {
        "type": "snapshot",
        "robots": robot_rows(Robot.objects.all()),
        "instructions": [_instruction_row(instruction) for instruction in recent],
    }


def robot_snapshot(robot) -> dict:
    """What a new robot-page subscriber sees first: the robot and its last state transitions."""
    transitions = robot.transitions.all()[:20]
    return {
        "type": "snapshot",
        "robots": robot_rows([robot]),
        "transitions": [
            {
                "from_state": record.from_state,
                "to_state": record.to_state,
                "at": record.at.isoformat(),
                "reason": record.reason,
                "instruction": record.instruction_id,
            }
            for record in transitions
        ],
    }
