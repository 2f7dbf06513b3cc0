"""One place that writes the audit trail."""

from fleet.models import AuditEntry


def record(user, action: str, target: str = "", /, **details) -> AuditEntry:
    """Store who did what to what; anonymous or system actions pass user=None."""
    user = user if getattr(user, "is_authenticated", False) else None
    return AuditEntry.objects.create(user=user, action=action, target=str(target)[:255], details=details)
