from django.contrib import admin

from audit.models import AuditEntry


@admin.register(AuditEntry)
class AuditEntryAdmin(admin.ModelAdmin):
    list_display = ("at", "user", "action", "target")
    list_filter = ("action",)
    search_fields = ("target",)

    def has_change_permission(self, request, obj=None):
        return False  # the audit trail is append-only
