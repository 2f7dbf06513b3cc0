from django.contrib import admin

from audit.models import AuditEntry


@admin.register(AuditEntry)
class AuditEntryAdmin(admin.ModelAdmin):
    """Read-only: the audit trail is append-only (audit.models.AuditEntry refuses changes below the admin too)."""

    list_display = ("at", "user", "action", "target")
    list_filter = ("action",)
    search_fields = ("target",)
    actions = None  # no "delete selected"

    def has_view_permission(self, request, obj=None):
        return request.user.has_perm("audit.view_auditentry")  # the "read_audit" row of access.roles

    def has_add_permission(self, request):
        return False

    def has_change_permission(self, request, obj=None):
        return False

    def has_delete_permission(self, request, obj=None):
        return False
