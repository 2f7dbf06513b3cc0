"""Robots in the JSON API: list, detail with bindings, and the choice of a binding by a person."""

from datetime import datetime

from ninja import Router, Schema, Status
from pydantic import Field

from access.roles import api_auth
from portal.api_types import Name, get_or_404
from robots.models import Binding, RegistrationRecord, Robot

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
    return Robot.objects.all()


@router.post("/register", response={200: RegisterOut, 202: RegisterOut}, auth=api_auth("register"))
def register_robots(request, payload: RegisterIn):
    """Register rosbridge endpoints: queued as a Celery task, or inline with wait=true.

    Each URL gets its own result; a queued registration answers with one record per URL at once, to be
    followed at GET /api/robots/registrations/{record} (and live on the registration page).
    """
    from ninja.errors import HttpError

    from robots.registration import abandon, begin, clean_urls
    from robots.tasks import register_endpoints

    urls = clean_urls(payload.endpoints)
    if not urls:
        raise HttpError(422, "endpoints: give at least one ws:// URL")
    if payload.wait:
        return Status(200, {"results": register_endpoints(urls, request.user.pk)})
    records = begin(urls, request.user)
    ids = [r.pk for r in records]
    try:
        task = register_endpoints.delay(urls, request.user.pk, ids)
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
        **RobotOut.from_orm(robot).dict(),
        "footprint": robot.footprint,
        "description": robot.description,
        "bindings": list(robot.bindings.all()),
    }


@router.put("/{name}/bindings/{action}", response=BindingOut, auth=api_auth("edit_bindings"))
def choose_binding(request, name: Name, action: Binding.Action, payload: BindingChoiceIn):
    """A person resolves a binding the engine was unsure of; the choice survives re-registration."""
    robot = get_or_404(Robot, "name", name=name)
    from robots.binding import choose

    return choose(robot, action, payload.target, request.user)
