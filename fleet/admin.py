"""The Django admin: staff users edit what their role's permissions allow (fleet.roles gives the groups them)."""

from django.contrib import admin

from fleet.models import (
    AuditEntry,
    ControlLease,
    Execution,
    ExperimentRun,
    Instruction,
    Location,
    Map,
    StateTransition,
    TimeSlot,
)
from fleet.roles import may


class LocationInline(admin.TabularInline):
    model = Location
    extra = 0


@admin.register(Map)
class MapAdmin(admin.ModelAdmin):
    list_display = ("name", "width", "height", "resolution", "source")
    exclude = ("data",)
    inlines = [LocationInline]


@admin.register(Location)
class LocationAdmin(admin.ModelAdmin):
    list_display = ("name", "map", "x", "y", "yaw", "kind")
    list_filter = ("map", "kind")
    search_fields = ("name",)


@admin.register(TimeSlot)
class TimeSlotAdmin(admin.ModelAdmin):
    list_display = ("robot", "start", "end", "goal", "task", "enabled", "last_run_on")
    list_filter = ("robot", "enabled")
    list_editable = ("start", "end", "goal", "task", "enabled")


class ExecutionInline(admin.TabularInline):
    model = Execution
    extra = 0
    readonly_fields = (
        "robot",
        "status",
        "steps",
        "dispatched_at",
        "first_command_at",
        "finished_at",
        "error",
    )


@admin.register(Instruction)
class InstructionAdmin(admin.ModelAdmin):
    list_display = ("id", "text", "user", "type", "status", "received_at", "finished_at")
    list_filter = ("type", "status", "source")
    search_fields = ("text",)
    date_hierarchy = "received_at"
    inlines = [ExecutionInline]


@admin.register(StateTransition)
class StateTransitionAdmin(admin.ModelAdmin):
    list_display = ("robot", "from_state", "to_state", "at", "instruction", "reason")
    list_filter = ("robot", "to_state")


@admin.register(ControlLease)
class ControlLeaseAdmin(admin.ModelAdmin):
    list_display = ("robot", "user", "taken_at", "expires_at")


@admin.register(AuditEntry)
class AuditEntryAdmin(admin.ModelAdmin):
    """Read-only: the audit trail is append-only (fleet.models.AuditEntry refuses changes below the admin too)."""

    list_display = ("at", "user", "action", "target")
    list_filter = ("action",)
    search_fields = ("target",)
    actions = None  # no "delete selected"

    def has_view_permission(self, request, obj=None):
        return may(request.user, "read_audit")

    def has_add_permission(self, request):
        return False

    def has_change_permission(self, request, obj=None):
        return False

    def has_delete_permission(self, request, obj=None):
        return False


@admin.register(ExperimentRun)
class ExperimentRunAdmin(admin.ModelAdmin):
    list_display = ("kind", "user", "status", "started_at", "finished_at")
