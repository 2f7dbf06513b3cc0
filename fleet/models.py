"""The fleet-wide domain: maps and locations, schedules, instructions and what the robots did with them."""

from django.conf import settings
from django.db import models
from django.utils import timezone

from robots.models import Robot


class Map(models.Model):
    """An occupancy grid in ROS map_server terms (cell (0, 0) at the lower left, row-major)."""

    name = models.CharField(max_length=100, unique=True)
    resolution = models.FloatField(help_text="metres per cell")
    width = models.PositiveIntegerField()
    height = models.PositiveIntegerField()
    origin_x = models.FloatField(default=0.0)
    origin_y = models.FloatField(default=0.0)
    origin_yaw = models.FloatField(default=0.0)
    data = models.BinaryField(help_text="one signed byte per cell: 0 free, 100 occupied, -1 unknown")
    source = models.CharField(max_length=255, blank=True, help_text="the map_server YAML it came from")
    created_at = models.DateTimeField(default=timezone.now)

    class Meta:
        ordering = ["name"]

    def __str__(self):
        return self.name

    @classmethod
    def from_grid(cls, name, grid, source=""):
        """Build (unsaved) from a fleet.mapfile.OccupancyGrid."""
        x, y, yaw = grid.origin
        data = bytes(value & 0xFF for value in grid.data)
        return cls(
            name=name,
            resolution=grid.resolution,
            width=grid.width,
            height=grid.height,
            origin_x=x,
            origin_y=y,
            origin_yaw=yaw,
            data=data,
            source=source,
        )

    def cells(self) -> list[int]:
        """The grid as signed ints, as nav_msgs/OccupancyGrid carries it."""
        return [value - 256 if value > 127 else value for value in bytes(self.data)]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) in metres."""
        return (
            self.origin_x,
            self.origin_y,
            self.origin_x + self.width * self.resolution,
            self.origin_y + self.height * self.resolution,
        )


class Location(models.Model):
    class Kind(models.TextChoices):
        ROOM = "room"
        WAYPOINT = "waypoint"

    map = models.ForeignKey(Map, on_delete=models.CASCADE, related_name="locations")
    name = models.CharField(max_length=100)
    x = models.FloatField()
    y = models.FloatField()
    yaw = models.FloatField(default=0.0)
    kind = models.CharField(max_length=10, choices=Kind.choices, default=Kind.WAYPOINT)

    class Meta:
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["map", "name"], name="location_unique_per_map")]

    def __str__(self):
        return self.name


class TimeSlot(models.Model):
    """A daily slot in which a robot goes to a goal and does a task (the paper's Tables 2 and 12)."""

    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="time_slots")
    start = models.TimeField()
    end = models.TimeField()
    goal = models.ForeignKey(Location, on_delete=models.PROTECT, related_name="time_slots")
    task = models.CharField(max_length=50, blank=True, help_text="e.g. rotate(5) or clean")
    enabled = models.BooleanField(default=True)
    last_run_on = models.DateField(null=True, blank=True)

    class Meta:
        ordering = ["robot", "start"]
        constraints = [
            models.CheckConstraint(
                condition=models.Q(start__lt=models.F("end")), name="timeslot_start_before_end"
            ),
        ]
        indexes = [models.Index(fields=["robot", "start", "end"])]
        permissions = [("edit_schedule", "Can edit robot schedules")]

    def __str__(self):
        return f"{self.robot} {self.start:%H:%M}-{self.end:%H:%M} {self.goal} {self.task}".strip()

    def covers(self, moment) -> bool:
        """Whether the slot is running at this local time."""
        return self.enabled and self.start <= moment < self.end


class Instruction(models.Model):
    """What a person typed, what the interpreter made of it, and how it ended."""

    class Type(models.TextChoices):
        PLAIN = "I", "I: plain"
        SYNONYM = "II", "II: synonym"
        SEMANTIC = "III", "III: semantic issue"
        SYNONYM_SEMANTIC = "IV", "IV: synonym and semantic issue"
        NOT_PROGRAMMED = "V", "V: not programmed"

    class Status(models.TextChoices):
        RECEIVED = "received"
        NEEDS_USER = "needs_user"
        REFUSED = "refused"
        QUEUED = "queued"
        RUNNING = "running"
        SUCCEEDED = "succeeded"
        FAILED = "failed"
        CANCELLED = "cancelled"

    FINAL = (Status.REFUSED, Status.SUCCEEDED, Status.FAILED, Status.CANCELLED)

    text = models.TextField()
    user = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL)
    robots = models.ManyToManyField(Robot, blank=True, related_name="instructions")
    parse = models.JSONField(default=dict, blank=True)
    type = models.CharField(max_length=3, choices=Type.choices, blank=True)
    status = models.CharField(max_length=12, choices=Status.choices, default=Status.RECEIVED)
    source = models.CharField(
        max_length=20, default="console", help_text="console, api, cli, schedule, teleop"
    )
    answer_to = models.ForeignKey(
        "self", null=True, blank=True, on_delete=models.SET_NULL, related_name="answers"
    )
    received_at = models.DateTimeField(default=timezone.now)
    interpreted_at = models.DateTimeField(null=True, blank=True)
    dispatched_at = models.DateTimeField(null=True, blank=True)
    first_command_at = models.DateTimeField(null=True, blank=True)
    motion_started_at = models.DateTimeField(null=True, blank=True)
    finished_at = models.DateTimeField(null=True, blank=True)
    outcome = models.TextField(blank=True, help_text="what happened, in words for a person")
    error = models.TextField(blank=True)

    class Meta:
        ordering = ["-received_at"]
        indexes = [
            models.Index(fields=["-received_at"]),
            models.Index(fields=["status", "-received_at"]),
            models.Index(fields=["user", "-received_at"]),
        ]

    def __str__(self):
        return f"#{self.pk} {self.text[:60]}"

    @property
    def is_final(self) -> bool:
        return self.status in self.FINAL


class Execution(models.Model):
    """One robot's share of one instruction: one step after another, each timed."""

    class Status(models.TextChoices):
        QUEUED = "queued"
        RUNNING = "running"
        SUCCEEDED = "succeeded"
        FAILED = "failed"
        CANCELLED = "cancelled"
        PREEMPTED = "preempted"

    instruction = models.ForeignKey(Instruction, on_delete=models.CASCADE, related_name="executions")
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="executions")
    status = models.CharField(max_length=10, choices=Status.choices, default=Status.QUEUED)
    priority = models.PositiveSmallIntegerField(default=0, help_text="work 3 > motion 2 > dialog 1 > ready 0")
    steps = models.JSONField(default=list, help_text="the interpreter's steps for this robot")
    step_index = models.PositiveSmallIntegerField(default=0)
    worker = models.CharField(max_length=255, blank=True, help_text="the Celery worker that claimed it")
    created_at = models.DateTimeField(default=timezone.now)
    dispatched_at = models.DateTimeField(null=True, blank=True)
    first_command_at = models.DateTimeField(null=True, blank=True)
    motion_started_at = models.DateTimeField(null=True, blank=True)
    finished_at = models.DateTimeField(null=True, blank=True)
    error = models.TextField(blank=True)

    class Meta:
        ordering = ["created_at"]
        constraints = [
            models.UniqueConstraint(fields=["instruction", "robot"], name="execution_unique_per_robot"),
        ]
        indexes = [models.Index(fields=["robot", "status", "created_at"])]

    def __str__(self):
        return f"{self.robot} #{self.instruction_id} {self.status}"


class StateTransition(models.Model):
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="transitions")
    from_state = models.CharField(max_length=12, choices=Robot.State.choices)
    to_state = models.CharField(max_length=12, choices=Robot.State.choices)
    at = models.DateTimeField(default=timezone.now)
    instruction = models.ForeignKey(
        Instruction, null=True, blank=True, on_delete=models.SET_NULL, related_name="transitions"
    )
    reason = models.CharField(max_length=255, blank=True)

    class Meta:
        ordering = ["-at"]
        indexes = [models.Index(fields=["robot", "-at"]), models.Index(fields=["instruction", "at"])]

    def __str__(self):
        return f"{self.robot}: {self.from_state} -> {self.to_state}"


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


class AppendOnlyError(Exception):
    """The audit trail only grows: an entry is never changed or deleted, by the admin or by code."""


class AuditQuerySet(models.QuerySet):
    """Audit rows are read and added; a bulk change or delete is refused (below the admin, for every caller)."""

    def _refuse(self, *args, **kwargs):
        raise AppendOnlyError("The audit trail is append-only: entries are never changed or deleted.")

    update = delete = bulk_update = update_or_create = _refuse


class AuditEntry(models.Model):
    """Who did what, when: every command, registration and ontology or schedule edit. Append-only.

    Deleting a user keeps their entries (the user becomes empty, the rest stays): Django's cascade updates them
    through its base manager, which is the one change allowed.
    """

    at = models.DateTimeField(default=timezone.now)
    user = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL)
    action = models.CharField(
        max_length=50, help_text="e.g. instruct, stop, teleop, register, ontology.teach"
    )
    target = models.CharField(max_length=255, blank=True)
    details = models.JSONField(default=dict, blank=True)

    objects = AuditQuerySet.as_manager()

    class Meta:
        ordering = ["-at"]
        verbose_name_plural = "audit entries"
        indexes = [models.Index(fields=["-at"]), models.Index(fields=["action", "-at"])]

    def __str__(self):
        return f"{self.at:%Y-%m-%d %H:%M:%S} {self.user} {self.action} {self.target}"

    def save(self, *args, **kwargs):
        """Insert once; saving an entry that is already stored is refused."""
        if not self._state.adding:
            raise AppendOnlyError("The audit trail is append-only: entries are never changed.")
        kwargs["force_insert"] = True
        super().save(*args, **kwargs)

    def delete(self, *args, **kwargs):
        raise AppendOnlyError("The audit trail is append-only: entries are never deleted.")


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
