from django.contrib import admin

from execution.models import Execution, Instruction, TimeSlot


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
