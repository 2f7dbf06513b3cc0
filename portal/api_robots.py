"""Robots in the JSON API: list (with pose and telemetry), detail with bindings, and the choice of a binding by a
person."""

import math
from datetime import datetime

from ninja import Router, Schema, Status
from ninja.errors import HttpError
from pydantic import Field

from access import holds
from access.roles import api_auth
from portal.api_types import Name, get_or_404
from robots import tasks
from robots.binding import choose
from robots.models import Binding, RegistrationRecord, Robot
from robots.poses import STALE_S, freshness, last_poses
from robots.registration import abandon, begin, clean_urls

router = Router(tags=["robots"])


class BindingOut(Schema):
    action: str
    target: str
    kind: str
    message_type: str
    how: str
    confidence: float
    needs_user: bool
    candidates: list


class PoseOut(Schema):
    """A robot's last pose with its telemetry, as the socket's fleet.poses carries it (live.RobotPose)."""

    x: float
    y: float
    yaw: float
    v: float = Field(description="linear speed, m/s")
    w: float = Field(description="angular speed, rad/s")
    t: float = Field(description="unix time the pose was taken")
    battery: float | None = Field(None, description="percent, when the robot has a battery topic bound")
    rtt: float | None = Field(None, description="ms, the link's round trip")


class RobotOut(Schema):
    id: int
    name: str
    model: str
    drive: str
    wheel_count: int | None
    max_linear: float
    max_angular: float
    endpoint: str
    namespace: str
    ros_version: int
    link_status: str
    state: str
    last_seen: datetime | None = Field(
        description="the freshest sign of life: its link's heartbeat or last pose"
    )
    pose_age: float | None = Field(description="seconds since its last pose was taken; null without one")
    stale: bool = Field(description=f"its pose is older than {STALE_S:g} s, or its odometry is refused")
    pose_fault: str | None = Field(description='why its odometry is refused now ("x is NaN"), else null')
    pose_status: str = Field(description='"live", "stale (3.2 s)", "odometry invalid: x is NaN" or "no pose"')
    stop_hold: str | None = Field(
        None, description='"held by a stop (admin, 10:43:44)": nothing automatic moves it; null when not held'
    )
    release: str | None = Field(None, description="how to release it, while a stop holds it")
    pose: PoseOut | None = Field(
        None, description="its last pose and telemetry (the socket's); null without one"
    )


def robot_rows(robots) -> list[dict]:
    """The robots with their pose health (robots.poses.freshness), as RobotOut reads them."""
    robots = list(robots)
    facts = freshness(robots)
    poses = last_poses([r.pk for r in robots])
    return [
        {
            **{f: getattr(r, f) for f in RobotOut.model_fields if hasattr(r, f)},
            **facts[r.pk],
            "stop_hold": r.hold_words,
            "release": _how_to_release(r),
            "pose": _pose(poses.get(r.pk)),
        }
        for r in robots
    ]


def _pose(pose: dict | None) -> dict | None:
    """The pose's fields RobotOut says (a finite number each, or no pose: the API's JSON is strict)."""
    if pose is None:
        return None
    shown = {k: pose.get(k) for k in PoseOut.model_fields}
    numbers = [v for v in shown.values() if v is not None]
    if not all(isinstance(v, int | float) and math.isfinite(v) for v in numbers) or None in (
        shown["x"],
        shown["y"],
        shown["yaw"],
        shown["t"],
    ):
        return None
    return {**shown, "v": shown["v"] or 0.0, "w": shown["w"] or 0.0}


def _how_to_release(robot) -> str | None:
    if robot.held_at is None:
        return None
    return f"POST /api/robots/{robot.name}/release, or {holds.how_to_release(robot.name)}"


class RobotDetailOut(RobotOut):
    footprint: list
    description: dict
    bindings: list[BindingOut]


class BindingChoiceIn(Schema):
    target: Name


class RegisterIn(Schema):
    endpoints: list[Name] = Field(max_length=1000)
    wait: bool = False


class EndpointResultOut(Schema):
    url: str
    ok: bool
    error: str
    robots: list[str]
    record: int | None


class RecordRef(Schema):
    url: str
    record: int


class RegisterOut(Schema):
    task_id: str | None = None
    results: list[EndpointResultOut] | None = None
    records: list[RecordRef] | None = None


class RegistrationOut(Schema):
    """One endpoint's registration: running until finished_at is set, then ok, or failed with the error."""

    id: int
    endpoint: str
    ok: bool
    error: str
    robots: list
    changes: dict
    started_at: datetime
    finished_at: datetime | None


@router.get("", response=list[RobotOut])
def list_robots(request):
    return robot_rows(Robot.objects.select_related("held_by"))


@router.post("/{name}/release", response=RobotOut, auth=api_auth("control"))
def release_hold(request, name: Name):
    """Release a robot a person's stop holds: the portal (make-way, "any robot", schedules) may move it again."""
    robot = get_or_404(Robot, "name", name=name)
    holds.release_by(request.user, [robot])
    robot.refresh_from_db()
    return robot_rows([robot])[0]


@router.post("/register", response={200: RegisterOut, 202: RegisterOut}, auth=api_auth("register"))
def register_robots(request, payload: RegisterIn):
    """Register rosbridge endpoints: queued as a Celery task, or inline with wait=true.

    Each URL gets its own result; a queued registration answers with one record per URL at once, to be
    followed at GET /api/robots/registrations/{record} (and live on the registration page).
    """
    urls = clean_urls(payload.endpoints)
    if not urls:
        raise HttpError(422, "endpoints: give at least one ws:// URL")
    if payload.wait:
        return Status(200, {"results": tasks.register_endpoints(urls, request.user.pk)})
    records = begin(urls, request.user)
    ids = [r.pk for r in records]
    try:
        task = tasks.register_endpoints.delay(urls, request.user.pk, ids)
    except Exception as exc:  # the queue is down: the records say so instead of staying "running"
        abandon(records, "not queued: the task queue was unreachable")
        raise HttpError(503, f"registration could not be queued ({type(exc).__name__}); try again") from exc
    return Status(
        202,
        {"task_id": task.id, "records": [{"url": u, "record": pk} for u, pk in zip(urls, ids, strict=True)]},
    )


@router.get("/registrations/{record_id}", response=RegistrationOut)
def registration_record(request, record_id: int):
    """The outcome of one endpoint's registration (queued ones included)."""
    return get_or_404(RegistrationRecord, "record_id", pk=record_id)


@router.get("/{name}", response=RobotDetailOut)
def robot_detail(request, name: Name):
    robot = get_or_404(Robot, "name", name=name)
    return {
        **robot_rows([robot])[0],
        "footprint": robot.footprint,
        "description": robot.description,
        "bindings": list(robot.bindings.all()),
    }


@router.put("/{name}/bindings/{action}", response=BindingOut, auth=api_auth("edit_bindings"))
def choose_binding(request, name: Name, action: Binding.Action, payload: BindingChoiceIn):
    """A person resolves a binding the engine was unsure of; the choice survives re-registration."""
    robot = get_or_404(Robot, "name", name=name)
    return choose(robot, action, payload.target, request.user)
