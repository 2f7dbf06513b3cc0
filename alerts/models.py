"""Alerts: incidents raised by the fleet, each open until a person (or the end of its condition) resolves it."""

from django.conf import settings
from django.db import models
from django.utils import timezone


class AlertQuerySet(models.QuerySet):
    def open(self):
        """Not resolved yet (acknowledged or not)."""
        return self.filter(resolved_at__isnull=True)

    def unacknowledged(self):
        return self.open().filter(acknowledged_at__isnull=True)

    def resolved(self):
        return self.filter(resolved_at__isnull=False)


class Alert(models.Model):
    class Kind(models.TextChoices):
        ROBOT_STUCK = "robot_stuck", "robot stuck"
        STEP_FAILED = "step_failed", "step failed"
        ROBOT_OFFLINE = "robot_offline", "robot offline"
        EXECUTOR_LOST = "executor_lost", "executor lost"
        LOW_BATTERY = "low_battery", "low battery"
        EMERGENCY_STOP = "emergency_stop", "emergency stop"
        PROCESS_HUNG = "process_hung", "process hung"  # no heartbeat (fleet/hangwatch.py); no robot
        ODOMETRY_INVALID = "odometry_invalid", "odometry invalid"
        STORE_REFUSED = "store_refused", "Redis or database refusing"
        LINK_FLOODING = "link_flooding", "link flooding"

    class Severity(models.TextChoices):
        INFO = "info"
        WARNING = "warning"
        CRITICAL = "critical"

    SEVERITY = {  # how loud each kind is: the one place that says it
        Kind.ROBOT_STUCK: Severity.WARNING,
        Kind.STEP_FAILED: Severity.WARNING,
        Kind.ROBOT_OFFLINE: Severity.WARNING,
        Kind.EXECUTOR_LOST: Severity.CRITICAL,
        Kind.LOW_BATTERY: Severity.WARNING,
        Kind.EMERGENCY_STOP: Severity.CRITICAL,
        Kind.PROCESS_HUNG: Severity.CRITICAL,
        Kind.ODOMETRY_INVALID: Severity.CRITICAL,
        Kind.STORE_REFUSED: Severity.CRITICAL,
        Kind.LINK_FLOODING: Severity.WARNING,
    }
    # Conditions the system sees end by themselves (alerts.resolve_alert): until it does, the event lasts, so a
    # person who resolves one early is not shown it again while it lasts. Any other event without a key ends
    # when a person resolves its alert.
    CONDITIONS = frozenset(
        {Kind.ROBOT_OFFLINE, Kind.LOW_BATTERY, Kind.ODOMETRY_INVALID, Kind.LINK_FLOODING, Kind.PROCESS_HUNG}
    )

    kind = models.CharField(max_length=20, choices=Kind.choices)
    severity = models.CharField(max_length=10, choices=Severity.choices, default=Severity.WARNING)
    robot = models.ForeignKey(
        "robots.Robot", null=True, blank=True, on_delete=models.SET_NULL, related_name="alerts"
    )
    message = models.TextField()
    event = models.CharField(
        max_length=64,
        blank=True,
        help_text="which occurrence ('execution 42', 'stop at …'); blank: the condition",
    )
    count = models.PositiveIntegerField(default=1, help_text="times raised for its event")
    raised_at = models.DateTimeField(default=timezone.now)
    last_raised_at = models.DateTimeField(default=timezone.now)
    acknowledged_by = models.ForeignKey(
        settings.AUTH_USER_MODEL, null=True, blank=True, on_delete=models.SET_NULL, related_name="+"
    )
    acknowledged_at = models.DateTimeField(null=True, blank=True)
    resolved_by = models.ForeignKey(
        settings.AUTH_USER_MODEL, null=True, blank=True, on_delete=models.SET_NULL, related_name="+"
    )
    resolved_at = models.DateTimeField(null=True, blank=True)
    resolution = models.CharField(max_length=255, blank=True, help_text="why it was resolved, in words")
    ended_at = models.DateTimeField(
        null=True, blank=True, help_text="when its event ended: a raise after it is a new event, a new alert"
    )

    objects = AlertQuerySet.as_manager()

    class Meta:
        ordering = ["-raised_at", "-pk"]
        indexes = [models.Index(fields=["resolved_at", "-raised_at"]), models.Index(fields=["kind", "robot"])]
        constraints = [
            models.UniqueConstraint(
                fields=["kind", "robot", "event"],
                condition=models.Q(resolved_at__isnull=True, robot__isnull=False),
                name="alert_one_open_per_kind_robot_and_event",
            ),
        ]

    def __str__(self):
        return f"{self.get_kind_display()}: {self.message[:60]}"

    @property
    def status(self) -> str:
        if self.resolved_at:
            return "resolved"
        return "acknowledged" if self.acknowledged_at else "open"
