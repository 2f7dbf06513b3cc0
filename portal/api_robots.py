"""Robots in the JSON API: list, detail with bindings, and the choice of a binding by a person."""

from datetime import datetime

from django.shortcuts import get_object_or_404
from ninja import Router, Schema, Status

from access.roles import REGISTER_PERM, require_perm
from robots.models import Binding, Robot

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
    last_seen: datetime | None


class RobotDetailOut(RobotOut):
    footprint: list
    description: dict
    bindings: list[BindingOut]


class BindingChoiceIn(Schema):
    target: str


class RegisterIn(Schema):
    endpoints: list[str]
    wait: bool = False


class EndpointResultOut(Schema):
    url: str
    ok: bool
    error: str
    robots: list[str]
    record: int | None


class RegisterOut(Schema):
    task_id: str | None = None
    results: list[EndpointResultOut] | None = None


@router.get("", response=list[RobotOut])
def list_robots(request):
    return Robot.objects.all()


@router.post("/register", response={200: RegisterOut, 202: RegisterOut})
def register_robots(request, payload: RegisterIn):
    """Register rosbridge endpoints: queued as a Celery task, or inline with wait=true."""
    require_perm(request, REGISTER_PERM)
    from ninja.errors import HttpError

    from robots.tasks import register_endpoints

    urls = [u.strip() for u in payload.endpoints if u.strip()]
    if not urls:
        raise HttpError(422, "endpoints: give at least one ws:// URL")
    if payload.wait:
        return Status(200, {"results": register_endpoints(urls, request.user.pk)})
    return Status(202, {"task_id": register_endpoints.delay(urls, request.user.pk).id})


@router.get("/{name}", response=RobotDetailOut)
def robot_detail(request, name: str):
    robot = get_object_or_404(Robot, name=name)
    return {
        **RobotOut.from_orm(robot).dict(),
        "footprint": robot.footprint,
        "description": robot.description,
        "bindings": list(robot.bindings.all()),
    }


@router.put("/{name}/bindings/{action}", response=BindingOut)
def choose_binding(request, name: str, action: Binding.Action, payload: BindingChoiceIn):
    """A person resolves a binding the engine was unsure of; the choice survives re-registration."""
    require_perm(request, REGISTER_PERM)
    robot = get_object_or_404(Robot, name=name)
    from robots.binding import choose

    return choose(robot, action, payload.target, request.user)
