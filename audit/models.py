"""The audit trail: who did what, when."""

from django.conf import settings
from django.db import models
from django.utils import timezone


class AppendOnlyError(Exception):
    """The audit trail only grows: an entry is never changed or deleted, by the admin or by code."""


class AuditQuerySet(models.QuerySet):
    """Audit rows are read and added; a bulk change or delete is refused (below the admin, for every caller)."""

    def _refuse(self, *args, **kwargs):
        raise AppendOnlyError("The audit trail is append-only: entries are never changed or deleted.")

    update = delete = bulk_update = update_or_create = _refuse


class AuditEntry(models.Model):
    """Who did what, when: every command, registration and ontology or schedule edit. Append-only.

    Deleting a user keeps their entries (the user becomes empty, the rest stays): Django's cascade updates them
    through its base manager, which is the one change allowed.
    """

    at = models.DateTimeField(default=timezone.now)
    user = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL)
    action = models.CharField(
        max_length=50, help_text="e.g. instruct, stop, teleop, register, ontology.teach"
    )
    target = models.CharField(max_length=255, blank=True)
    details = models.JSONField(default=dict, blank=True)

    objects = AuditQuerySet.as_manager()

    class Meta:
        ordering = ["-at"]
        verbose_name_plural = "audit entries"
        indexes = [models.Index(fields=["-at"]), models.Index(fields=["action", "-at"])]

    def __str__(self):
        return f"{self.at:%Y-%m-%d %H:%M:%S} {self.user} {self.action} {self.target}"

    def save(self, *args, **kwargs):
        """Insert once; saving an entry that is already stored is refused."""
        if not self._state.adding:
            raise AppendOnlyError("The audit trail is append-only: entries are never changed.")
        kwargs["force_insert"] = True
        super().save(*args, **kwargs)

    def delete(self, *args, **kwargs):
        raise AppendOnlyError("The audit trail is append-only: entries are never deleted.")
