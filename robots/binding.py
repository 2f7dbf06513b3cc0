"""A person's choice of the topic or action behind one action of one robot, checked against what it accepts."""

from ninja.errors import HttpError

from audit import records as audit
from robots.models import Binding, Robot, TargetRefused


class BindingRefused(HttpError):
    """A target the robot does not have, or of a type its action cannot use: a 422 naming the field."""

    def __init__(self, message: str) -> None:
        super().__init__(422, message)


def resolve_target(robot: Robot, action: str, target: str) -> tuple[str, str]:
    """(kind, message type) of a target the robot has and the action accepts (Binding.resolve); BindingRefused,
    a 422 naming the field, says why not."""
    try:
        return Binding.resolve(robot, action, target)
    except TargetRefused as exc:
        raise BindingRefused(str(exc)) from None


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
