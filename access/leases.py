"""Who holds control of a robot: a lease with expiry, visible to all; admins may take it over.

An operator commands a robot that nobody holds, or that they hold themselves. Viewers never command.
"""

from datetime import timedelta

from django.conf import settings
from django.contrib.auth import get_user_model
from django.db import transaction
from django.utils import timezone

import live
from access.models import ControlLease
from access.roles import can_control, can_take_over
from audit import records as audit


class ControlRefused(Exception):
    """The user may not command this robot now; the message says why, in words."""


def active(robots):
    """The leases held now on these robots (a queryset, users joined)."""
    return ControlLease.objects.filter(robot__in=robots, expires_at__gt=timezone.now()).select_related("user")


def holders(robot_ids, known=None) -> dict:
    """{robot id: the user holding its lease now} for these robots, in one query of ids; `known` (a user the caller
    has, the person pressing) stands for its own leases, and other holders are read in one more query only when
    there are any. A fleet's teleop re-check reads this every half second: no user row built for each robot."""
    rows = list(
        ControlLease.objects.filter(robot_id__in=robot_ids, expires_at__gt=timezone.now()).values_list(
            "robot_id", "user_id"
        )
    )
    mine = getattr(known, "pk", None)
    others = get_user_model().objects.in_bulk({uid for _, uid in rows if uid != mine})
    return {rid: known if uid == mine else others[uid] for rid, uid in rows if uid == mine or uid in others}


def holder(robot):
    """The user holding the robot's lease now, or None."""
    lease = active([robot]).first()
    return lease.user if lease else None


_ASK = object()


def check_command(user, robot, held_by=_ASK) -> None:
    """Raise ControlRefused unless the user may command the robot now (held_by: its holder, if known)."""
    if not can_control(user):
        raise ControlRefused(f"{user.username} may only view robots, not command them.")
    if held_by is _ASK:
        held_by = holder(robot)
    if held_by is not None and held_by != user:
        raise ControlRefused(f"{robot.name} is held by {held_by.username}; ask them to release it.")


def check_teleop(user, robot, held_by=_ASK) -> None:
    """Driving by hand needs the lease (operators, access.roles "control"): a free robot's is taken for the
    driver on the first command (audited and shown on every page), so nobody else drives it meanwhile; someone
    else's lease refuses (ControlRefused). Instructions need no lease: they queue and run by the robot's rules."""
    if held_by is _ASK:
        held_by = holder(robot)
    check_command(user, robot, held_by)
    if held_by is None:
        take(user, robot)


def check_stop(user) -> None:
    """Raise ControlRefused unless the user may stop robots: any operator stops any robot, held or not.

    A lease keeps others from driving a robot, never from stopping it: a stop always gets through.
    """
    if not can_control(user):
        raise ControlRefused(f"{user.username} may only view robots, not command them.")


def check_cancel(user, owner, robots, held_by=None) -> None:
    """Raise ControlRefused unless the user may cancel an instruction of `owner` (None: the system's) that these
    robots run: viewers never; an operator their own always (a cancel is their own word taken back); another's
    or the system's as they may command every robot of it (a robot someone else holds is theirs to decide);
    an admin any. held_by: {robot id: its holder}, if known."""
    if not can_control(user):
        raise ControlRefused(f"{user.username} may only view robots, not command them.")
    if owner == user or can_take_over(user):
        return
    holders = held_by if held_by is not None else {lease.robot_id: lease.user for lease in active(robots)}
    for robot in robots:
        check_command(user, robot, held_by=holders.get(robot.pk))


@transaction.atomic
def take(user, robot, seconds: int | None = None) -> ControlLease:
    """Take (or renew) control of a robot; an admin takes over from anyone."""
    if not can_control(user):
        raise ControlRefused(f"{user.username} may only view robots, not command them.")
    seconds = seconds or settings.FLEET_CONTROL_LEASE_SECONDS
    lease = ControlLease.objects.select_for_update().filter(robot=robot).first()
    now = timezone.now()
    if lease and lease.expires_at > now and lease.user != user and not can_take_over(user):
        raise ControlRefused(
            f"{robot.name} is held by {lease.user.username} until {lease.expires_at:%H:%M:%S}."
        )
    taken_over = lease.user.username if lease and lease.expires_at > now and lease.user != user else None
    lease, _ = ControlLease.objects.update_or_create(
        robot=robot, defaults={"user": user, "taken_at": now, "expires_at": now + timedelta(seconds=seconds)}
    )
    audit.record(user, "control.take", robot.name, taken_over_from=taken_over, seconds=seconds)
    live.lease(robot, lease)  # on commit: every page, and every socket's teleop grant for the robot, sees it
    return lease


def release(user, robot) -> bool:
    """Give control back; only the holder or an admin can."""
    lease = ControlLease.objects.filter(robot=robot).first()
    if lease is None:
        return False
    if lease.user != user and not can_take_over(user):
        raise ControlRefused(f"{robot.name} is held by {lease.user.username}, not by you.")
    lease.delete()
    audit.record(user, "control.release", robot.name)
    live.lease(robot, None)
    return True
