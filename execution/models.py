"""Instructions, each robot's share of them (executions), and the robots' daily time slots."""

from datetime import timedelta

from django.conf import settings
from django.db import models
from django.urls import reverse
from django.utils import timezone

from places.models import Location
from robots.models import Robot


class TimeSlotQuerySet(models.QuerySet):
    def running_at(self, local_time):
        """Enabled slots running at this local wall-clock time (schedules are in local time)."""
        return self.filter(enabled=True, start__lte=local_time, end__gt=local_time)


class TimeSlot(models.Model):
    """A daily slot in which a robot goes to a goal and does a task (the paper's Tables 2 and 12)."""

    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="time_slots")
    start = models.TimeField()
    end = models.TimeField()
    goal = models.ForeignKey(Location, on_delete=models.PROTECT, related_name="time_slots")
    task = models.CharField(max_length=50, blank=True, help_text="e.g. rotate(5) or clean")
    enabled = models.BooleanField(default=True)
    last_run_on = models.DateField(null=True, blank=True)

    objects = TimeSlotQuerySet.as_manager()

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


EXPIRED = "expired: no answer within"  # the note of a question nobody answered in time (execution/sweeps.py)


class InstructionQuerySet(models.QuerySet):
    FINAL = ("refused", "succeeded", "failed", "cancelled")

    def in_progress_list(self):
        """What the console's Progress list shows: all but the questions that expired unanswered."""
        return self.exclude(status="cancelled", outcome__contains=f"({EXPIRED}")

    def open(self):
        """Not final yet: received, needs_user, queued or running."""
        return self.exclude(status__in=self.FINAL)

    def final(self):
        return self.filter(status__in=self.FINAL)

    def older_than(self, status: str, seconds: float, now=None, since: str = "received_at"):
        """Instructions in this status whose `since` stamp is older than `seconds` (a sweep's deadline)."""
        moment = (now or timezone.now()) - timedelta(seconds=seconds)
        return self.filter(status=status, **{f"{since}__lt": moment})


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
        ANSWERED = "answered"  # a question the person answered: the answer ran as a new instruction

    FINAL = (Status.REFUSED, Status.SUCCEEDED, Status.FAILED, Status.CANCELLED, Status.ANSWERED)

    text = models.TextField()
    user = models.ForeignKey(settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL)
    robots = models.ManyToManyField(Robot, blank=True, related_name="instructions")
    parse = models.JSONField(default=dict, blank=True)
    type = models.CharField(max_length=3, choices=Type.choices, blank=True)
    status = models.CharField(max_length=12, choices=Status.choices, default=Status.RECEIVED)
    source = models.CharField(
        max_length=20, default="console", help_text="console, api, cli, schedule, traffic, teleop"
    )
    cause = models.CharField(
        max_length=255, blank=True, help_text="why the system sent it (no user): e.g. make way for husky, #14"
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

    objects = InstructionQuerySet.as_manager()

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
    def expired(self) -> bool:
        """A question nobody answered in time: cancelled by the sweep with its note; gone from Progress."""
        return self.status == self.Status.CANCELLED and f"({EXPIRED}" in self.outcome

    @property
    def is_final(self) -> bool:
        return self.status in self.FINAL

    def photo_urls(self) -> list[str]:
        """Where to see the photos its robots took (the photograph action), oldest first."""
        photos = Photo.objects.filter(execution__instruction=self).only("pk")
        return [photo.get_absolute_url() for photo in photos]


class ExecutionQuerySet(models.QuerySet):
    WAITING = ("queued", "preempted")
    FINAL = ("succeeded", "failed", "cancelled")

    def waiting(self):
        """Executions that have not started, or were preempted and wait to go on."""
        return self.filter(status__in=self.WAITING)

    def final(self):
        return self.filter(status__in=self.FINAL)

    def waiting_for_offline_robots(self, seconds: float, now=None):
        """Waiting executions of robots whose link is down and that nobody has seen for `seconds`."""
        moment = (now or timezone.now()) - timedelta(seconds=seconds)
        offline = models.Q(robot__last_seen__lt=moment) | models.Q(
            robot__last_seen__isnull=True, robot__registered_at__lt=moment
        )
        return self.waiting().filter(offline, robot__link_status="offline")

    def current_work(self, robot_ids, running_only: bool = False) -> tuple[dict, dict]:
        """Per robot: the instruction it is working on ({id, text, status}) and its goal ({name, x, y})."""
        current, goals = {}, {}
        active = ("running",) if running_only else ("running", "queued")
        rows = self.filter(robot_id__in=robot_ids, status__in=active).select_related("instruction")
        for execution in rows.order_by("queued_at", "pk"):
            if execution.robot_id in current:
                continue
            steps = execution.steps or []
            current[execution.robot_id] = {
                "id": execution.instruction_id,
                "text": execution.instruction.text,
                "status": execution.status,
                "step": min(execution.step_index, len(steps) - 1) + 1 if steps else None,
                "steps": len(steps),
            }
            step = steps[min(execution.step_index, len(steps) - 1)] if steps else {}
            destination = step.get("destination") if isinstance(step, dict) else None
            if destination and destination.get("x") is not None:
                goals[execution.robot_id] = {
                    "name": destination.get("name"),
                    "x": destination["x"],
                    "y": destination["y"],
                }
        return current, goals


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
    queued_at = models.DateTimeField(
        default=timezone.now,
        help_text="its place in the robot's queue (oldest first); moved up or down by a person",
    )
    dispatched_at = models.DateTimeField(null=True, blank=True)
    first_command_at = models.DateTimeField(null=True, blank=True)
    motion_started_at = models.DateTimeField(null=True, blank=True)
    finished_at = models.DateTimeField(null=True, blank=True)
    outcome = models.TextField(blank=True, help_text="what the robot did, in words (its handlers' answers)")
    error = models.TextField(blank=True)

    objects = ExecutionQuerySet.as_manager()

    class Meta:
        ordering = ["created_at"]
        constraints = [
            models.UniqueConstraint(fields=["instruction", "robot"], name="execution_unique_per_robot"),
        ]
        indexes = [
            models.Index(fields=["robot", "status", "created_at"]),
            models.Index(fields=["robot", "status", "queued_at"]),
        ]

    def __str__(self):
        return f"{self.robot} #{self.instruction_id} {self.status}"

    @property
    def event(self) -> str:
        """What the alerts call this execution: whatever befalls it (a stall, the failure it ends in, its executor
        lost) is one event, one alert (alerts.raise_alert)."""
        return f"execution {self.pk}"


class Photo(models.Model):
    """A frame a robot's camera took for an instruction (the photograph action), kept as the image itself."""

    execution = models.ForeignKey(Execution, on_delete=models.CASCADE, related_name="photos")
    image = models.BinaryField(help_text="the PNG or JPEG, as a browser shows it")
    format = models.CharField(max_length=4, help_text="png or jpeg")
    width = models.PositiveIntegerField()
    height = models.PositiveIntegerField()
    topic = models.CharField(max_length=255, help_text="the camera topic it came from")
    taken_at = models.DateTimeField(default=timezone.now)

    class Meta:
        ordering = ["taken_at", "pk"]

    def __str__(self):
        return f"{self.execution.robot} #{self.execution.instruction_id} {self.width}×{self.height} {self.format}"

    def get_absolute_url(self) -> str:
        return reverse("photo", args=[self.pk])

    @property
    def content_type(self) -> str:
        return f"image/{self.format}"
