"""Raise, acknowledge and resolve alerts: one open alert per kind and robot, every change pushed and audited."""

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


def raise_alert(kind: str, robot=None, message: str = "") -> Alert | None:
    """Open an alert, or count a repeat of the open one of the same kind and robot; push it.

    Called from the paths that stop robots and settle instructions: an alert that cannot be stored is logged,
    never raised into the caller.
    """
    try:
        return _raise(Alert.Kind(kind), robot, message)
    except Exception:
        log.exception("alert %s for %s not stored: %s", kind, getattr(robot, "name", None), message)
        return None


def _raise(kind: Alert.Kind, robot, message: str) -> Alert:
    now = timezone.now()
    for _ in range(2):  # a second raiser may open the same alert between our look and our insert
        with transaction.atomic():
            alert = Alert.objects.open().filter(kind=kind, robot=robot).select_for_update().first()
            if alert is not None:
                alert.count += 1
                alert.message, alert.last_raised_at = message[:2000], now
                alert.save(update_fields=["count", "message", "last_raised_at"])
                _push(alert)
                return alert
            try:
                with transaction.atomic():
                    alert = Alert.objects.create(
                        kind=kind, severity=Alert.SEVERITY[kind], robot=robot, message=message[:2000],
                        raised_at=now, last_raised_at=now,
                    )  # fmt: skip
            except IntegrityError:
                continue
            audit.record(None, "alert.raise", _target(alert), kind=kind.value, message=alert.message)
            _push(alert)
            return alert
    raise IntegrityError(f"alert {kind} for {robot}: could not be opened or found")


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
    """A person closes the alert (its cause dealt with)."""
    with transaction.atomic():
        alert = _open_alert(alert_id)
        _close(alert, user, note or f"resolved by {user.username}")
        audit.record(user, "alert.resolve", _target(alert), kind=alert.kind, note=note)
    return alert


def resolve_open(kind: str, robot=None, note: str = "") -> Alert | None:
    """Close the open alert of this kind and robot because its condition ended (a robot back online)."""
    try:
        with transaction.atomic():
            alert = Alert.objects.open().filter(kind=kind, robot=robot).select_for_update().first()
            if alert is None:
                return None
            _close(alert, None, note or "condition ended")
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


def _close(alert: Alert, user, note: str) -> None:
    alert.resolved_by, alert.resolved_at, alert.resolution = user, timezone.now(), note[:255]
    alert.save(update_fields=["resolved_by", "resolved_at", "resolution"])
    _push(alert)


def _target(alert: Alert) -> str:
    return f"alert {alert.pk} ({alert.robot.name if alert.robot_id else 'fleet'})"


def _push(alert: Alert) -> None:
    live.alert(as_dict(alert), open_count())
