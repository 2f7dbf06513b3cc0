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
    # progress, for the page: steps done of the run's total (response: grid cells per robot; success: trials)
    done = models.PositiveIntegerField(default=0)
    total = models.PositiveIntegerField(default=0)

    FINAL = ("succeeded", "failed")

    class Meta:
        ordering = ["-started_at"]

    def __str__(self):
        return f"{self.kind} {self.started_at:%Y-%m-%d %H:%M}"

    @property
    def is_final(self) -> bool:
        return self.status in self.FINAL

    def as_dict(self) -> dict:
        """What the page's live status shows of a run."""
        return {
            "id": self.pk,
            "kind": self.kind,
            "status": self.status,
            "done": self.done,
            "total": self.total,
            "started_at": self.started_at.isoformat(),
            "finished_at": self.finished_at.isoformat() if self.finished_at else None,
            "error": (self.results or {}).get("error", ""),
        }
