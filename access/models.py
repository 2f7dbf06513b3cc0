"""Who holds control of which robot."""

from django.conf import settings
from django.db import models
from django.utils import timezone

from robots.models import Robot


class ControlLease(models.Model):
    """Who holds control of a robot now; nobody else commands it until release or expiry."""

    robot = models.OneToOneField(Robot, on_delete=models.CASCADE, related_name="lease")
    user = models.ForeignKey(settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="leases")
    taken_at = models.DateTimeField(default=timezone.now)
    expires_at = models.DateTimeField()

    class Meta:
        indexes = [models.Index(fields=["expires_at"])]

    def __str__(self):
        return f"{self.robot} held by {self.user}"

    @property
    def active(self) -> bool:
        return self.expires_at > timezone.now()
