"""A stop holds: a robot a person stopped stays where it is until a person releases it or names it again.

Nothing automatic moves a held robot: traffic's make-way, the choice of "any robot" (or "all robots"), a
schedule's slot, an instruction queued before the stop (execution.dispatch and execution.runner ask here). A
person's instruction naming the robot releases it (dispatch says so in the answer), as do "release tiago", the
Release buttons and the API. A person's teleop still drives a held robot: a person moves it, not the portal.

The hold is three fields of Robot (held_at, held_by, held_reason); its words are Robot.hold_words.
"""

from __future__ import annotations

from django.utils import timezone

import live
from access import leases
from access.leases import ControlRefused
from access.roles import can_control
from audit import records as audit
from robots.models import STATUS_FIELDS, Robot

AUTOMATIC = frozenset({"schedule", "traffic"})  # instruction sources that are the system's, not a person's


def is_automatic(source: str) -> bool:
    """Whether an instruction of this source is the system's (a schedule's slot, traffic's make-way)."""
    return source in AUTOMATIC


def how_to_release(name: str) -> str:
    return f'type "release {name}", press Release on its page, or give it an instruction naming it'


def hold(robots, user, reason: str = "a stop") -> None:
    """A person stopped these robots: hold them (again, from now, by that person)."""
    ids = [robot.pk for robot in robots]
    Robot.objects.filter(pk__in=ids).update(held_at=timezone.now(), held_by=user, held_reason=reason)
    for robot in (
        Robot.objects.filter(pk__in=ids).select_related("held_by").only(*STATUS_FIELDS, "held_by__username")
    ):
        live.robot_status(robot)


def release(robots, user, why: str = "released") -> dict[str, str]:
    """Release the held ones of these robots: {name: what held it}, for those that were held."""
    held = list(
        Robot.objects.filter(pk__in=[r.pk for r in robots], held_at__isnull=False).select_related("held_by")
    )
    if not held:
        return {}
    words = {robot.name: robot.hold_words for robot in held}
    Robot.objects.filter(pk__in=[r.pk for r in held]).update(held_at=None, held_by=None, held_reason="")
    audit.record(user, "hold.release", ", ".join(words)[:255], why=why, held=words)
    for robot in held:
        robot.held_at, robot.held_by, robot.held_reason = None, None, ""
        live.robot_status(robot)
    return words


def release_by(user, robots) -> dict[str, str]:
    """A person's release (console, buttons, API): ControlRefused for a viewer."""
    if not can_control(user):
        raise ControlRefused(f"{user.username} may only view robots, not release them.")
    return release(robots, user)


def refusal(robot: Robot) -> str:
    """Why nothing automatic may move this held robot, and how a person lets it go."""
    return (
        f"{robot.name} is {robot.hold_words}: nothing automatic moves it until a person releases it "
        f"({how_to_release(robot.name)})"
    )


def check_automatic(robots) -> None:
    """ControlRefused unless the system may move each of these robots: held by no stop and leased by nobody."""
    robots = list(robots)
    fresh = {r.pk: r for r in Robot.objects.filter(pk__in=[r.pk for r in robots]).select_related("held_by")}
    for robot in fresh.values():
        if robot.held_at is not None:
            raise ControlRefused(refusal(robot))
    for lease in leases.active(list(fresh)):
        name = fresh[lease.robot_id].name
        raise ControlRefused(
            f"{name} is held by {lease.user.username} (control lease): the system leaves it be."
        )
