from django.contrib import admin

from alerts.models import Alert


@admin.register(Alert)
class AlertAdmin(admin.ModelAdmin):
    list_display = (
        "raised_at",
        "kind",
        "severity",
        "robot",
        "message",
        "count",
        "acknowledged_by",
        "resolved_at",
    )
    list_filter = ("kind", "severity")
    search_fields = ("message",)
