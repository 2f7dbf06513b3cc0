from django.contrib import admin

from recordings.models import Recording


@admin.register(Recording)
class RecordingAdmin(admin.ModelAdmin):
    list_display = ("pk", "user", "seconds", "status", "started_at", "path")
    readonly_fields = ("counts", "error")
