"""Registered robots and the ROS graph discovered behind each rosbridge endpoint."""

import logging
import re

from django.core.exceptions import ValidationError
from django.db import models
from django.utils import timezone

import live
from fleetcore import grammar
from fleetcore.bindings import ROLES, norm_type
from fleetcore.states import IllegalTransition, next_state
from fleetcore.states import State as RobotState
from robots import endpoints, identify
from robots.rosbridge.errors import RosbridgeError

log = logging.getLogger(__name__)


class RobotManager(models.Manager):
    def transition(self, robot, event: str, reason: str = "", instruction=None):
        """Apply an event to a robot's state (the table in fleetcore.states); store and push the transition.

        None when the event is illegal in the robot's state now. A compare-and-set on the state (no
        read-then-write transaction), so concurrent runners never interleave.
        """
        robot_id = robot if isinstance(robot, int) else robot.pk
        for _ in range(5):
            current = self.get(pk=robot_id)
            try:
                to_state = next_state(current.state, event)
            except IllegalTransition as exc:
                log.info("%s: %s (%s)", current.name, exc, reason)
                return None
            if self.filter(pk=robot_id, state=current.state).update(state=to_state):
                return current._record_transition(to_state, reason, instruction)
        return None


ROBOT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")


def validate_robot_name(name: str) -> None:
    """Letters, digits, dash and underscore, starting with a letter or digit; not only digits; not a word
    instructions use (the parser's own keywords: fleetcore.grammar.reserved). So a name is one word the
    interpreter can only read as that robot, never as grammar ("move and to A")."""
    if not ROBOT_NAME.fullmatch(name or ""):
        raise ValidationError(
            "%(name)r: a robot name uses letters, digits, dashes and underscores only (no spaces).",
            code="robot_name",
            params={"name": name},
        )
    if name.isdigit() or grammar.reserved(name):
        raise ValidationError(
            "%(name)r: a robot name must not be a number or a word instructions use (and, then, to, from, slowly, stop, ...).",
            code="robot_name_reserved",
            params={"name": name},
        )


def robot_name_from(text: str) -> str:
    """A valid robot name made from what a robot says of itself (URDF name, namespace) or its host-port:
    other characters become dashes; a number or a reserved word gets the prefix "robot-"."""
    name = re.sub(r"[^A-Za-z0-9_-]+", "-", text or "").strip("-_")[:90] or "robot"
    return f"robot-{name}" if name.isdigit() or grammar.reserved(name) else name


# What live.robot_status pushes of a robot (its hold_words too, with the holder's username): the columns to read
# when a robot is loaded only to say its status (a stop's holds: no footprint or URDF facts for each robot stopped).
STATUS_FIELDS = ("id", "name", "link_status", "state", "last_seen", "held_at", "held_by", "held_reason")


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

    # The paper's Figure 5 states; the one enum of them is fleetcore.states.State (transitions: its table).
    State = models.TextChoices("State", [(state.name, state.value) for state in RobotState])

    name = models.CharField(
        max_length=100,
        unique=True,
        validators=[validate_robot_name],
        help_text="letters, digits, dashes and underscores; e.g. husky, tb3_0, robot-2",
    )
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
    # A stop's hold (access.holds): a robot a person stopped stays put; nothing automatic moves it until a
    # person releases it or gives it an instruction naming it. Held while held_at is set.
    held_at = models.DateTimeField(null=True, blank=True)
    held_by = models.ForeignKey(
        "auth.User", null=True, blank=True, on_delete=models.SET_NULL, related_name="+"
    )
    held_reason = models.CharField(max_length=40, blank=True, help_text='what holds it, e.g. "a stop"')

    objects = RobotManager()

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

    @property
    def hold_words(self) -> str | None:
        """ "held by a stop (admin, 10:43:44)" while a stop holds the robot, else None (the pages, the API)."""
        if self.held_at is None:
            return None
        who = self.held_by.username if self.held_by_id else "a user since deleted"
        return f"held by {self.held_reason or 'a stop'} ({who}, {timezone.localtime(self.held_at):%H:%M:%S})"

    def transition(self, event: str, reason: str = "", instruction=None):
        """Apply an event to this robot's state; see RobotManager.transition."""
        record = Robot.objects.transition(self.pk, event, reason, instruction)
        if record is not None:
            self.state = record.to_state
        return record

    def _record_transition(self, to_state: str, reason: str, instruction):
        record = StateTransition.objects.create(
            robot=self,
            from_state=self.state,
            to_state=to_state,
            at=timezone.now(),
            reason=reason[:255],
            instruction_id=instruction if isinstance(instruction, int) else getattr(instruction, "pk", None),
        )
        self.state = to_state
        live.transition(self, record)
        live.robot_status(self)
        return record

    def clean(self):
        """An endpoint typed in the admin is checked as registration checks it, and stored by its address."""
        try:
            self.endpoint = endpoints.check(self.endpoint, endpoints.allow_list())
        except RosbridgeError as exc:
            raise ValidationError({"endpoint": str(exc)}) from None


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

    # The roles of fleetcore/bindings.py, the one table of them.
    Action = models.TextChoices("Action", [(name.upper(), name) for name in ROLES])

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
        try:
            self.kind, self.message_type = Binding.resolve(self.robot, self.action, self.target)
        except TargetRefused as exc:
            raise ValidationError({"target": str(exc)}) from None

    @staticmethod
    def resolve(robot: Robot, action: str, target: str) -> tuple[str, str]:
        """(kind, message type) of a target the robot has and the action accepts; TargetRefused says why not."""
        found = _target_of(robot, target)
        if found is None:
            raise TargetRefused(f"target: {target!r} is not a topic or action of {robot.name}")
        kind, type_ = found
        if not identify.accepts(action, kind, type_):
            raise TargetRefused(
                f"target: {target} is a {type_ or 'untyped'} {kind}; {action} takes {identify.accepted(action)}"
            )
        return kind, type_


class TargetRefused(ValueError):
    """A binding's target the robot does not have, or of a type its action cannot use."""


def _target_of(robot: Robot, target: str) -> tuple[str, str] | None:
    """(kind, type) of one of the robot's names; action servers are stored with its services, by their type."""
    topic = robot.topics.filter(name=target).first()
    if topic:
        return Binding.Kind.TOPIC, topic.type
    service = robot.services.filter(name=target).first()
    if service:
        is_action = norm_type(service.type) in identify.NAV_ACTION_TYPES
        return (Binding.Kind.ACTION if is_action else Binding.Kind.SERVICE), service.type
    return None


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


class StateTransition(models.Model):
    robot = models.ForeignKey(Robot, on_delete=models.CASCADE, related_name="transitions")
    from_state = models.CharField(max_length=12, choices=Robot.State.choices)
    to_state = models.CharField(max_length=12, choices=Robot.State.choices)
    at = models.DateTimeField(default=timezone.now)
    instruction = models.ForeignKey(
        "execution.Instruction", null=True, blank=True, on_delete=models.SET_NULL, related_name="transitions"
    )
    reason = models.CharField(max_length=255, blank=True)

    class Meta:
        ordering = ["-at"]
        indexes = [models.Index(fields=["robot", "-at"]), models.Index(fields=["instruction", "at"])]

    def __str__(self):
        return f"{self.robot}: {self.from_state} -> {self.to_state}"
