"""Alerts in the JSON API: viewers list them, operators acknowledge and resolve them (both audited)."""

from datetime import datetime

from ninja import Query, Router, Schema
from ninja.errors import HttpError

from access.roles import api_auth
from alerts import service
from alerts.models import Alert
from portal.api_types import Text, path_id

router = Router(tags=["alerts"])

LISTS = {  # ?status= -> the alerts it shows
    "open": lambda: Alert.objects.open(),
    "unacknowledged": lambda: Alert.objects.unacknowledged(),
    "resolved": lambda: Alert.objects.resolved(),
    "all": lambda: Alert.objects.all(),
}


class AlertOut(Schema):
    id: int
    kind: str
    kind_label: str
    severity: str
    robot: str | None
    robot_id: int | None
    message: str
    event: str  # "execution 42", "stop at …"; "" for a condition while it lasts
    count: int
    raised_at: datetime
    last_raised_at: datetime
    status: str
    acknowledged_by: str | None
    acknowledged_at: datetime | None
    resolved_by: str | None
    resolved_at: datetime | None
    resolution: str


class ResolveIn(Schema):
    note: Text = ""


@router.get("", response=list[AlertOut], auth=api_auth("view_alerts"))
def list_alerts(request, status: str = "open", limit: int = Query(100, ge=1, le=500)):
    """Alerts, newest first: open (default), unacknowledged, resolved or all."""
    if status not in LISTS:
        raise HttpError(422, f"status: expected one of {', '.join(LISTS)}, got {status[:40]!r}")
    rows = LISTS[status]().select_related("robot", "acknowledged_by", "resolved_by")[:limit]
    return [service.as_dict(alert) for alert in rows]


@router.post("/{alert_id}/acknowledge", response=AlertOut, auth=api_auth("handle_alerts"))
def acknowledge(request, alert_id: int = path_id()):
    """Take the alert on (it stays open until resolved)."""
    return service.as_dict(_apply(service.acknowledge, alert_id, request.user))


@router.post("/{alert_id}/resolve", response=AlertOut, auth=api_auth("handle_alerts"))
def resolve(request, payload: ResolveIn | None = None, alert_id: int = path_id()):
    """Close the alert, with a note on what was done."""
    return service.as_dict(_apply(service.resolve, alert_id, request.user, payload.note if payload else ""))


ERRORS = {service.UnknownAlert: 404, service.AlertClosed: 409}  # the answer each refusal gets


def _apply(action, alert_id: int, *args) -> Alert:
    try:
        return action(alert_id, *args)
    except service.AlertError as exc:
        raise HttpError(ERRORS[type(exc)], f"alert_id: {exc}") from exc
