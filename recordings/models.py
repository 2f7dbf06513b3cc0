"""A recording of the fleet for later review: an MCAP file under var/recordings/ and what it holds."""

from django.conf import settings
from django.db import models
from django.utils import timezone


class Recording(models.Model):
    """One recording: who asked, for how long, where its file is, how many messages of each topic it holds."""

    class Status(models.TextChoices):
        QUEUED = "queued"
        RECORDING = "recording"
        FINISHED = "finished"
        FAILED = "failed"

    user = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, blank=True, on_delete=models.SET_NULL)
    seconds = models.FloatField()
    raw_topics = models.JSONField(default=list, blank=True)  # ["robot:/cmd_vel", ...] also recorded as sent
    path = models.CharField(max_length=500)
    status = models.CharField(max_length=12, choices=Status.choices, default=Status.QUEUED)
    started_at = models.DateTimeField(default=timezone.now)
    finished_at = models.DateTimeField(null=True, blank=True)
    counts = models.JSONField(default=dict, blank=True)  # topic -> messages written
    error = models.TextField(blank=True)

    class Meta:
        ordering = ["-started_at"]

    def __str__(self):
        return f"recording {self.pk} ({self.seconds:g} s, {self.status})"

    @property
    def messages(self) -> int:
        return sum(self.counts.values())
