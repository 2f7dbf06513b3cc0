"""A person's choice of the topic or action behind one action of one robot, checked against what it accepts."""

from ninja.errors import HttpError

from audit import records as audit
from fleetcore.bindings import norm_type
from robots import identify
from robots.models import Binding, Robot


class BindingRefused(HttpError):
    """A target the robot does not have, or of a type its action cannot use: a 422 naming the field."""

    def __init__(self, message: str) -> None:
        super().__init__(422, message)


def resolve_target(robot: Robot, action: str, target: str) -> tuple[str, str]:
    """(kind, message type) of a target the robot has and the action accepts; BindingRefused says why not."""
    found = _find(robot, target)
    if found is None:
        raise BindingRefused(f"target: {target!r} is not a topic or action of {robot.name}")
    kind, type_ = found
    if not identify.accepts(action, kind, type_):
        raise BindingRefused(
            f"target: {target} is a {type_ or 'untyped'} {kind}; {action} takes {identify.accepted(action)}"
        )
    return kind, type_


def _find(robot: Robot, target: str) -> tuple[str, str] | None:
    """(kind, type) of one of the robot's names; action servers are stored with its services, by their type."""
    topic = robot.topics.filter(name=target).first()
    if topic:
        return Binding.Kind.TOPIC, topic.type
    service = robot.services.filter(name=target).first()
    if service:
        is_action = norm_type(service.type) in identify.NAV_ACTION_TYPES
        return (Binding.Kind.ACTION if is_action else Binding.Kind.SERVICE), service.type
    return None


def choose(robot: Robot, action: str, target: str, user) -> Binding:
    """Bind an action to the target a person chose; registration keeps it while the target exists."""
    kind, message_type = resolve_target(robot, action, target)
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
