"""Raise, acknowledge and resolve alerts: one alert per event, every change pushed and audited."""

from __future__ import annotations

import logging

from django.db import IntegrityError, transaction
from django.utils import timezone

import live
from alerts.models import Alert
from audit import records as audit

log = logging.getLogger(__name__)


class AlertError(ValueError):
    """An alert that cannot take this change; the message says why."""


class UnknownAlert(AlertError):
    """No alert has this id."""


class AlertClosed(AlertError):
    """The alert was resolved already: nothing more to acknowledge or resolve."""


def raise_alert(kind: str, robot=None, message: str = "", event: str = "") -> Alert | None:
    """Open an alert for a new event, or count a repeat of the same event on its alert; push it.

    One alert per event. With a key (`event`: "execution 42"), the event is that robot's and key's, whatever the
    kind: a stall's robot_stuck and the step_failed it ends in are one alert, which takes the later kind and
    words. Without one, the event is the kind's condition for that robot while it lasts (Alert.CONDITIONS: until
    resolve_alert says it ended; any other kind: until a person resolves it). A repeat of an event a person has
    resolved is counted, not shown again. Called from the paths that stop robots and settle instructions: an
    alert that cannot be stored is logged, never raised into the caller.
    """
    try:
        return _raise(Alert.Kind(kind), robot, message, event[:64])
    except Exception:
        log.exception("alert %s for %s not stored: %s", kind, getattr(robot, "name", None), message)
        return None


def _raise(kind: Alert.Kind, robot, message: str, event: str) -> Alert:
    now = timezone.now()
    for _ in range(2):  # a second raiser may open the same alert between our look and our insert
        with transaction.atomic():
            alert = _same_event(kind, robot, event)
            if alert is not None:
                return _repeat(alert, kind, message, now)
            try:
                with transaction.atomic():
                    alert = Alert.objects.create(
                        kind=kind, severity=Alert.SEVERITY[kind], robot=robot, message=message[:2000],
                        event=event, raised_at=now, last_raised_at=now,
                    )  # fmt: skip
            except IntegrityError:
                continue
            audit.record(None, "alert.raise", _target(alert), kind=kind.value, message=alert.message)
            _push(alert)
            return alert
    raise IntegrityError(f"alert {kind} for {robot}: could not be opened or found")


def _same_event(kind: Alert.Kind, robot, event: str) -> Alert | None:
    """The alert of this event (locked), open or resolved by a person while the event lasts; None: a new event."""
    same = Alert.objects.filter(robot=robot, event=event, ended_at__isnull=True)
    if not event:
        same = same.filter(kind=kind)
    return same.order_by("-pk").select_for_update().first()


def _repeat(alert: Alert, kind: Alert.Kind, message: str, now) -> Alert:
    """Count a repeat on the event's alert: open, it takes the latest kind and words; resolved, it stays so."""
    alert.count, alert.last_raised_at = alert.count + 1, now
    if alert.resolved_at is not None:  # a person has dealt with this event: not shown again
        alert.save(update_fields=["count", "last_raised_at"])
        return alert
    alert.kind, alert.severity, alert.message = kind, Alert.SEVERITY[kind], message[:2000]
    alert.save(update_fields=["count", "last_raised_at", "kind", "severity", "message"])
    _push(alert)
    return alert


def acknowledge(alert_id: int, user) -> Alert:
    """A person has seen the alert and takes it on; it stays open until resolved."""
    with transaction.atomic():
        alert = _open_alert(alert_id)
        if alert.acknowledged_at is None:
            alert.acknowledged_by, alert.acknowledged_at = user, timezone.now()
            alert.save(update_fields=["acknowledged_by", "acknowledged_at"])
            audit.record(user, "alert.acknowledge", _target(alert), kind=alert.kind)
            _push(alert)
    return alert


def resolve(alert_id: int, user, note: str = "") -> Alert:
    """A person closes the alert (its cause dealt with). A condition's event lasts until the condition ends."""
    with transaction.atomic():
        alert = _open_alert(alert_id)
        _close(alert, user, note or f"resolved by {user.username}", ended=alert.kind not in Alert.CONDITIONS)
        audit.record(user, "alert.resolve", _target(alert), kind=alert.kind, note=note)
    return alert


def resolve_open(kind: str, robot=None, note: str = "") -> Alert | None:
    """Close the open alert of this kind and robot because its condition ended (a robot back online); the
    condition's event ends, so the next raise is a new alert, even where a person had resolved it early."""
    try:
        with transaction.atomic():
            lasting = Alert.objects.filter(kind=kind, robot=robot, event="", ended_at__isnull=True)
            alert = lasting.open().select_for_update().first()
            lasting.resolved().update(ended_at=timezone.now())
            if alert is None:
                return None
            _close(alert, None, note or "condition ended", ended=True)
            audit.record(None, "alert.resolve", _target(alert), kind=alert.kind, note=alert.resolution)
            return alert
    except Exception:
        log.exception("alert %s for %s not resolved", kind, getattr(robot, "name", None))
        return None


def open_count() -> int:
    return Alert.objects.open().count()


def as_dict(alert: Alert) -> dict:
    """The alert as the API, the page and the push show it."""
    return {
        "id": alert.pk,
        "kind": alert.kind,
        "kind_label": alert.get_kind_display(),
        "severity": alert.severity,
        "robot": alert.robot.name if alert.robot_id else None,
        "robot_id": alert.robot_id,
        "message": alert.message,
        "event": alert.event,
        "count": alert.count,
        "raised_at": alert.raised_at.isoformat(),
        "last_raised_at": alert.last_raised_at.isoformat(),
        "status": alert.status,
        "acknowledged_by": alert.acknowledged_by.username if alert.acknowledged_by_id else None,
        "acknowledged_at": alert.acknowledged_at.isoformat() if alert.acknowledged_at else None,
        "resolved_by": alert.resolved_by.username if alert.resolved_by_id else None,
        "resolved_at": alert.resolved_at.isoformat() if alert.resolved_at else None,
        "resolution": alert.resolution,
    }


def _open_alert(alert_id: int) -> Alert:
    alert = Alert.objects.select_for_update().filter(pk=alert_id).first()
    if alert is None:
        raise UnknownAlert(f"no alert has the id {alert_id}")
    if alert.resolved_at is not None:
        raise AlertClosed(f"alert {alert_id} was already resolved ({alert.resolution})")
    return alert


def _close(alert: Alert, user, note: str, ended: bool) -> None:
    alert.resolved_by, alert.resolved_at, alert.resolution = user, timezone.now(), note[:255]
    alert.ended_at = (
        alert.resolved_at if ended and not alert.event else None
    )  # a keyed event lasts as its key
    alert.save(update_fields=["resolved_by", "resolved_at", "resolution", "ended_at"])
    _push(alert)


def _target(alert: Alert) -> str:
    return f"alert {alert.pk} ({alert.robot.name if alert.robot_id else 'fleet'})"


def _push(alert: Alert) -> None:
    live.alert(as_dict(alert), open_count())
