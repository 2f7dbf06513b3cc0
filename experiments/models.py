"""Experiment runs started from the experiments page."""

from django.conf import settings
from django.db import models
from django.utils import timezone

from robots.models import Robot


class ExperimentRun(models.Model):
    """One run of a response-time or success-rate experiment from the experiments page."""

    kind = models.CharField(max_length=30)
    user = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL)
    robots = models.ManyToManyField(Robot, blank=True)
    params = models.JSONField(default=dict, blank=True)
    started_at = models.DateTimeField(default=timezone.now)
    finished_at = models.DateTimeField(null=True, blank=True)
    status = models.CharField(max_length=12, default="queued")
    results = models.JSONField(default=dict, blank=True)

    class Meta:
        ordering = ["-started_at"]

    def __str__(self):
        return f"{self.kind} {self.started_at:%Y-%m-%d %H:%M}"
