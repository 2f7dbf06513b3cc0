from django.contrib import admin

from experiments.models import ExperimentRun


@admin.register(ExperimentRun)
class ExperimentRunAdmin(admin.ModelAdmin):
    list_display = ("kind", "user", "status", "started_at", "finished_at")
