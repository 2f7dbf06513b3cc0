"""One place that writes the audit trail."""

from audit.models import AuditEntry


def record(user, action: str, target: str = "", /, **details) -> AuditEntry:
    """Store who did what to what; anonymous or system actions pass user=None."""
    user = user if getattr(user, "is_authenticated", False) else None
    return AuditEntry.objects.create(user=user, action=action, target=str(target)[:255], details=details)


def record_many(user, action: str, entries) -> list[AuditEntry]:
    """Store several entries of one user and action in one write: (target, at, details) each."""
    user = user if getattr(user, "is_authenticated", False) else None
    rows = [
        AuditEntry(user=user, action=action, target=str(t)[:255], at=at, details=d) for t, at, d in entries
    ]
    return AuditEntry.objects.bulk_create(rows)
