"""A person's choice of the topic, service or action behind one action of one robot."""

from ninja.errors import HttpError

from audit import records as audit
from robots.models import Binding, Robot


def resolve_target(robot: Robot, target: str) -> tuple[str, str]:
    """(kind, message type) of a name the robot has, or a 422 naming the field."""
    topic = robot.topics.filter(name=target).first()
    if topic:
        return Binding.Kind.TOPIC, topic.type
    service = robot.services.filter(name=target).first()
    if service:
        return Binding.Kind.SERVICE, service.type
    raise HttpError(422, f"target: {target!r} is not a topic or service of {robot.name}")


def choose(robot: Robot, action: str, target: str, user) -> Binding:
    """Bind an action to the target a person chose; registration keeps it while the target exists."""
    kind, message_type = resolve_target(robot, target)
    binding, _ = Binding.objects.update_or_create(
        robot=robot,
        action=action,
        defaults={
            "target": target,
            "kind": kind,
            "message_type": message_type,
            "how": Binding.How.USER,
            "confidence": 1.0,
            "needs_user": False,
        },
    )
    audit.record(user, "binding.choose", robot.name, action=action, target=target)
    return binding
