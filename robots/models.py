"""Registered robots and the ROS graph discovered behind each rosbridge endpoint."""

from django.core.exceptions import ValidationError
from django.db import models
from django.utils import timezone


class Robot(models.Model):
    """One robot reachable through a rosbridge endpoint, possibly under a namespace."""

    class Drive(models.TextChoices):
        WHEELED = "wheeled"
        LEGGED = "legged"
        OTHER = "other"

    class Link(models.TextChoices):
        ONLINE = "online"
        OFFLINE = "offline"
        REGISTERING = "registering"

    class State(models.TextChoices):
        """The paper's Figure 5 states; the order of PRIORITY is work > motion > dialog > ready."""

        REGISTERED = "registered"
        READY = "ready"
        DIALOG = "dialog"
        MOTION = "motion"
        WORK = "work"
        OFFLINE = "offline"

    name = models.CharField(max_length=100, unique=True)
    model = models.CharField(max_length=100, blank=True, help_text="e.g. turtlebot3_burger, husky, tiago")
    drive = models.CharField(max_length=10, choices=Drive.choices, default=Drive.OTHER)
    wheel_count = models.PositiveSmallIntegerField(null=True, blank=True)
    leg_count = models.PositiveSmallIntegerField(null=True, blank=True)
    footprint = models.JSONField(
        default=list, blank=True, help_text="polygon [[x, y], ...] in metres, base frame"
    )
    max_linear = models.FloatField(default=0.22, help_text="m/s")
    max_angular = models.FloatField(default=2.84, help_text="rad/s")
    endpoint = models.CharField(max_length=255, help_text="rosbridge WebSocket URL, e.g. ws://10.0.0.5:9090")
    namespace = models.CharField(max_length=100, blank=True, help_text='"" or e.g. /robot1')
    ros_version = models.PositiveSmallIntegerField(choices=[(1, "ROS 1"), (2, "ROS 2")], default=1)
    link_status = models.CharField(max_length=12, choices=Link.choices, default=Link.REGISTERING)
    last_seen = models.DateTimeField(null=True, blank=True)
    state = models.CharField(max_length=12, choices=State.choices, default=State.REGISTERED)
    start_pose = models.JSONField(
        default=list, blank=True, help_text="[x, y, yaw] of the odometry origin on the map"
    )
    description = models.JSONField(default=dict, blank=True, help_text="facts read from the URDF")
    registered_at = models.DateTimeField(default=timezone.now)
    updated_at = models.DateTimeField(auto_now=True)

    class Meta:
        ordering = ["name"]
        constraints = [
            models.UniqueConstraint(fields=["endpoint", "namespace"], name="robot_unique_endpoint_namespace"),
        ]
        indexes = [models.Index(fields=["link_status", "state"]), models.Index(fields=["endpoint"])]
        permissions = [
            ("control_robot", "Can command and teleoperate robots"),
            ("register_robot", "Can register robots from rosbridge endpoints"),
        ]

    def __str__(self):
        return self.name

    def clean(self):
        """An endpoint typed in the admin is checked as registration checks it, and stored by its address."""
        from robots import endpoints
        from robots.registration import allow_list
        from robots.rosbridge import RosbridgeError

        try:
            self.endpoint = endpoints.check(self.endpoint, allow_list())
        except RosbridgeError as exc:
            raise ValidationError({"endpoint": str(exc)}) from None

    def topic_name(self, relative: str) -> str:
        """Resolve a robot-relative topic name under this robot's namespace."""
        return f"{self.namespace.rstrip('/')}/{relative.lstrip('/')}"


class Topic(models.Model):
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="topics")
    name = models.CharField(max_length=255)
    type = models.CharField(max_length=255, blank=True)
    publishers = models.JSONField(default=list, blank=True)
    subscribers = models.JSONField(default=list, blank=True)

    class Meta:
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["robot", "name"], name="topic_unique_per_robot")]

    def __str__(self):
        return f"{self.name} ({self.type})"


class Node(models.Model):
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="nodes")
    name = models.CharField(max_length=255)
    publishing = models.JSONField(default=list, blank=True)
    subscribing = models.JSONField(default=list, blank=True)
    services = models.JSONField(default=list, blank=True)

    class Meta:
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["robot", "name"], name="node_unique_per_robot")]

    def __str__(self):
        return self.name


class Service(models.Model):
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="services")
    name = models.CharField(max_length=255)
    type = models.CharField(max_length=255, blank=True)

    class Meta:
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["robot", "name"], name="service_unique_per_robot")]

    def __str__(self):
        return self.name


class Param(models.Model):
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="params")
    name = models.CharField(max_length=255)
    value = models.TextField(blank=True, help_text="JSON text, as rosapi/get_param returns it")

    class Meta:
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["robot", "name"], name="param_unique_per_robot")]

    def __str__(self):
        return self.name


class Binding(models.Model):
    """Which topic, service or action carries one action of one robot, and how that was decided."""

    class Action(models.TextChoices):
        MOVE = "move"
        ODOMETRY = "odometry"
        POSE = "pose"
        NAVIGATE = "navigate"
        SCAN = "scan"
        MAP = "map"
        INITIAL_POSE = "initial_pose"
        BATTERY = "battery"

    class How(models.TextChoices):
        EXACT = "exact"
        PATTERN = "pattern"
        SYNONYM = "synonym"
        USER = "user"
        NONE = "none"

    class Kind(models.TextChoices):
        TOPIC = "topic"
        SERVICE = "service"
        ACTION = "action"

    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="bindings")
    action = models.CharField(max_length=20, choices=Action.choices)
    target = models.CharField(
        max_length=255, blank=True, help_text="topic, service or action name; blank if unbound"
    )
    kind = models.CharField(max_length=10, choices=Kind.choices, default=Kind.TOPIC)
    message_type = models.CharField(max_length=255, blank=True)
    how = models.CharField(max_length=10, choices=How.choices, default=How.NONE)
    confidence = models.FloatField(default=0.0)
    needs_user = models.BooleanField(default=False)
    candidates = models.JSONField(
        default=list, blank=True, help_text="[{target, type, score, how}] kept for a person"
    )
    updated_at = models.DateTimeField(auto_now=True)

    class Meta:
        ordering = ["robot", "action"]
        constraints = [models.UniqueConstraint(fields=["robot", "action"], name="binding_unique_action")]
        indexes = [models.Index(fields=["needs_user"])]

    def __str__(self):
        return f"{self.robot}.{self.action} -> {self.target or '?'}"

    def clean(self):
        """A target must be one of the robot's names, of a type the action accepts (the admin's forms ask this)."""
        if not self.target or self.robot_id is None:
            return
        from robots.binding import BindingRefused, resolve_target

        try:
            self.kind, self.message_type = resolve_target(self.robot, self.action, self.target)
        except BindingRefused as exc:
            raise ValidationError({"target": exc.message}) from None


class RegistrationRecord(models.Model):
    """One registration of one endpoint: when, by whom, the outcome and what changed."""

    endpoint = models.CharField(max_length=255)
    user = models.ForeignKey("auth.User", null=True, blank=True, on_delete=models.SET_NULL)
    started_at = models.DateTimeField(default=timezone.now)
    finished_at = models.DateTimeField(null=True, blank=True)
    ok = models.BooleanField(default=False)
    error = models.TextField(blank=True)
    robots = models.JSONField(default=list, blank=True, help_text="names of the robots found")
    changes = models.JSONField(
        default=dict, blank=True, help_text="per robot: topics added/removed, bindings changed"
    )

    class Meta:
        ordering = ["-started_at"]
        indexes = [models.Index(fields=["endpoint", "-started_at"])]

    def __str__(self):
        return f"{self.endpoint} at {self.started_at:%Y-%m-%d %H:%M:%S}"
