"""Direct control: stop and teleoperation, published from the calling process, bypassing every queue.

stop() publishes a zero velocity on each robot's move topic at once and cancels its navigation goal
(robots/commands.py CommandSurface.zero: move_base's cancel topic, nav2's cancel_goal service), then raises the robots' stop flags (running executions
see them on their next control tick), cancels the robots' queued executions and, for a person's stop, holds the
robots (access.holds: nothing automatic moves them until a person releases them); a failure of that bookkeeping
is said in its results, never raised.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from django.core.cache import cache
from django.db import DatabaseError
from django.utils import timezone

import alerts
import live
from access import holds, leases
from access.leases import ControlRefused, check_stop
from audit import records as audit
from execution import coordination
from execution.bookkeeping import brief_lock_wait
from execution.link import LinkError, publish_zero
from execution.models import Execution
from execution.runner import settle
from fleetcore import faults, motion
from robots.commands import ROW_FIELDS, CommandSurface, kept_surfaces, marked_rows
from robots.models import Robot
from robots.rosbridge import pool as links
from robots.rosbridge import sync

log = logging.getLogger(__name__)

WAITING = (Execution.Status.QUEUED, Execution.Status.PREEMPTED)


def _robots(robots) -> list[Robot]:
    """Robots from robots, names or primary keys (those read with the columns a stop or a press needs)."""
    robots = list(robots)
    if robots and all(isinstance(r, Robot) for r in robots):
        return robots
    names = [r for r in robots if isinstance(r, str)]
    pks = [r for r in robots if isinstance(r, int)]
    found = [
        *Robot.objects.filter(name__in=names).only(*ROW_FIELDS),
        *Robot.objects.filter(pk__in=pks).only(*ROW_FIELDS),
    ]
    missing = set(names) - {r.name for r in found}
    if missing:
        raise ValueError(f"No robot named {', '.join(sorted(missing))} is registered.")
    return found


class StopResults(dict):
    """{robot name: "stopped" or why it was not reached}, and what of the stop's bookkeeping failed afterwards
    (`unrecorded`: "Redis refuses writes ...", "the database is locked ..."), for the answer to say."""

    def __init__(self, results) -> None:
        super().__init__(results)
        self.failed: dict[str, str] = {}  # store ("Redis", "the database") -> what went wrong, in words

    @property
    def unrecorded(self) -> list[str]:
        return list(dict.fromkeys(self.failed.values()))

    def note(self) -> str:
        """What the answer adds when some bookkeeping failed ("Could not record it: ..."); "" otherwise."""
        return f" Could not record it: {'; '.join(self.unrecorded)}." if self.failed else ""


def stop(robots, user, source: str = "console", database_fault: str | None = None) -> StopResults:
    """Stop these robots now; return {robot name: "stopped" or the reason it could not be reached}.

    The zeros go first, each robot's on its own; then the flags (Redis), the queued executions, the audit and
    the alert, each of which may fail (a Redis frozen or refusing writes, a locked database) without undoing the
    stop: what failed is logged and listed in the results' `unrecorded`, and once a store failed the rest of its
    bookkeeping is skipped. database_fault: the words of a database failure the caller already met (skipped).
    """
    robots = _robots(robots)
    if user is not None:
        check_stop(user)  # held robots too: a lease never blocks a stop
    try:  # every robot's surface at once, its bindings read only if they changed since this process read them
        kept = kept_surfaces(marked_rows(Robot.objects.filter(pk__in=[r.pk for r in robots])))
    except DatabaseError as exc:  # each robot's zero then reads its own, and says why it could not
        log.warning("stop: command surfaces not read at once: %s", exc)
        kept = {}
    surfaces = [kept.get(robot.pk) for robot in robots]
    with ThreadPoolExecutor(max_workers=min(8, max(1, len(robots)))) as pool:
        zeros = pool.map(_publish_zero, robots, surfaces)
        results = StopResults(zip([r.name for r in robots], zeros, strict=True))
    if database_fault:
        results.failed["the database"] = database_fault
    with brief_lock_wait(), live.together():  # its pushes (a status per robot) in one hand-over
        _bookkeeping(results, robots, user, source)
    return results


def _bookkeeping(results: StopResults, robots: list[Robot], user, source: str) -> None:
    """What a stop records after its zeros: the flags, the queued executions cancelled, the hold, the audit, the
    alert."""
    ids = [robot.pk for robot in robots]
    _record(results, "Redis", coordination.request_stop, ids)
    _record(results, "the database", cancel_waiting, robots, "stopped")
    if user is not None:  # a person's stop holds: nothing automatic moves these robots until a person says so
        _record(results, "the database", holds.hold, robots, user)
    names = ", ".join(r.name for r in robots)[:255]
    _record(results, "the database", audit.record, user, "stop", names, source=source, results=dict(results))
    if robots and _record(results, "the database", lambda: len(set(ids)) == Robot.objects.count()):
        _record(results, "the database", _raise_emergency_stop, user, source)


def _raise_emergency_stop(user, source: str) -> None:
    """Each stop of every robot is its own event, with its own time and person: its own alert (a later stop
    does not rewrite an earlier one's words under its first time)."""
    who = getattr(user, "username", None) or "the system"
    message = f"a stop of every robot, by {who} ({source})"
    alerts.raise_alert("emergency_stop", None, message, event=f"stop at {timezone.now().isoformat()}")


def _record(stop_results: StopResults, store: str, action, *args, **kwargs):
    """Run one piece of a stop's bookkeeping unless its store already failed in this stop; a failure is logged
    and noted in results, never raised."""
    if store in stop_results.failed:
        return None
    try:
        return action(*args, **kwargs)
    except Exception as exc:
        log.warning("stop: %s failed after the zeros: %r", getattr(action, "__name__", action), exc)
        stop_results.failed[store] = faults.in_words(exc, store)
        return None


def _publish_zero(robot: Robot, surface: CommandSurface | None = None) -> str:
    try:
        publish_zero(robot, surface)
    except (LinkError, Exception) as exc:  # one unreachable robot must not keep the others moving
        log.warning("stop %s: %s", robot.name, exc)
        return f"not reached: {exc}"
    return "stopped"


def cancel_waiting(robots, reason: str) -> int:
    """Cancel the robots' queued (and preempted) executions and settle their instructions."""
    rows = list(
        Execution.objects.filter(robot__in=robots, status__in=WAITING).values_list("pk", "instruction_id")
    )
    done = Execution.objects.filter(pk__in=[pk for pk, _ in rows], status__in=WAITING).update(
        status=Execution.Status.CANCELLED, finished_at=timezone.now(), error=reason
    )
    for instruction_id in {iid for _, iid in rows}:
        settle(instruction_id)
    return done


HELD_REPEAT_S = 2  # a held button repeats every 0.2 s; a longer gap is a new press


@dataclass(frozen=True)
class TeleopGrant:
    """What the checks of one teleop command established: where to publish, within which limits, until when.

    A held button sends a command every 0.2 s. The portal's WebSocket keeps one grant per robot and publishes
    the repeats under it without the database; it drops the grant when the robot's lease or state changes
    (pushed to every page) and re-checks all its grants at once every GRANT_S while they are used.
    """

    surface: CommandSurface
    max_linear: float
    max_angular: float
    expires: float

    @property
    def robot_id(self) -> int:
        return self.surface.robot_id

    @property
    def robot_name(self) -> str:
        return self.surface.name

    @property
    def endpoint(self) -> str:
        return self.surface.endpoint

    @property
    def valid(self) -> bool:
        return time.monotonic() < self.expires

    def clamp(self, linear: float, angular: float) -> tuple[float, float]:
        return motion.clamp(float(linear), self.max_linear), motion.clamp(float(angular), self.max_angular)

    def publish(self, v: float, w: float):
        """The (topic, message, type) that sends this velocity to the robot."""
        return self.surface.velocity(v, w, 0.0)


GRANT_S = 1.0


def teleop_grants(robot_ids, user) -> dict[int, TeleopGrant | Exception]:
    """Check at once that the user may drive each robot now: {robot id: its grant, or the refusal}.

    Three queries whatever the number of robots, a fourth for the bindings of robots whose surface this process
    has not read yet or that changed since (robots.commands.kept_surfaces), so a socket holding many buttons
    checks them cheaply. Refusals: ControlRefused (role, someone else's lease, a running instruction), LinkError
    (no move topic), ValueError (no such robot).
    """
    ids = list(dict.fromkeys(robot_ids))
    rows = marked_rows(Robot.objects.filter(pk__in=ids), "max_linear", "max_angular")
    robots = {robot.pk: robot for robot in rows}
    found = list(robots)
    held = leases.holders(found, user)
    busy = dict(
        Execution.objects.filter(robot__in=found, status=Execution.Status.RUNNING).values_list(
            "robot_id", "instruction_id"
        )
    )
    commands = kept_surfaces(robots.values())
    expires = time.monotonic() + GRANT_S
    out: dict[int, TeleopGrant | Exception] = {}
    with live.together():  # the leases taken (a push each: a fleet's first presses) go in one message a group
        for pk in ids:
            out[pk] = _grant(user, robots.get(pk), pk, held, busy, commands, expires)
    return out


def _grant(user, robot, pk, held, busy, commands, expires) -> TeleopGrant | Exception:
    """One robot's grant of teleop_grants, or its refusal."""
    if robot is None:
        return ValueError(f"robot {pk}: no such robot")
    try:
        leases.check_command(user, robot, held_by=held.get(pk))
    except ControlRefused as exc:
        return exc
    if pk in busy:
        return ControlRefused(f"{robot.name} is running instruction #{busy[pk]}; stop it first.")
    if not commands[pk].can_move:
        return LinkError(f"{robot.name}: no move topic is bound")
    return _leased(user, robot, held.get(pk)) or TeleopGrant(
        commands[pk], robot.max_linear, robot.max_angular, expires
    )


def _leased(user, robot, held_by) -> ControlRefused | None:
    """Take a free robot's lease for its driver (access.leases.check_teleop); the refusal if it went meanwhile."""
    try:
        leases.check_teleop(user, robot, held_by=held_by)
    except ControlRefused as exc:
        return exc
    return None


def teleop_grant(robot, user) -> TeleopGrant:
    """Check that the user may drive the robot now and find its move topic (ControlRefused / LinkError)."""
    robot = _robots([robot])[0]
    grant = teleop_grants([robot.pk], user)[robot.pk]
    if isinstance(grant, Exception):
        raise grant
    return grant


def teleop_with(grant: TeleopGrant, user, linear: float, angular: float) -> tuple[float, float]:
    """Publish one velocity command under a grant, within the robot's limits; return what was sent."""
    v, w = grant.clamp(linear, angular)
    try:
        client = sync.get_client(grant.endpoint)
    except Exception as exc:  # unreachable endpoint, timeout: a one-line reason for the person
        raise LinkError(f"{grant.robot_name}: cannot reach {grant.endpoint}: {exc}") from exc
    client.publish(*grant.publish(v, w))
    _audit_teleop(user, grant, v, w)
    return v, w


async def publish_teleop(grant: TeleopGrant, linear: float, angular: float) -> tuple[float, float]:
    """teleop_with for code on an event loop: one send on the loop's own link, no thread, no database.

    The caller audits changes (audit_teleops, from a thread); a held button's repeats need no audit.
    """
    v, w = grant.clamp(linear, angular)
    try:
        client = await links.client(grant.endpoint)
        await client.publish(*grant.publish(v, w))
    except Exception as exc:  # the link is down or went down: a one-line reason for the person
        raise LinkError(f"{grant.robot_name}: cannot reach {grant.endpoint}: {exc}") from exc
    return v, w


def link_idle(endpoint: str) -> bool:
    """Whether publish_teleop to this endpoint would go out now: its link on this loop up and not backed up."""
    return links.idle(endpoint)


def teleop(robot, user, linear: float, angular: float) -> tuple[float, float]:
    """Publish one velocity command within the robot's limits; return what was sent.

    Refused (ControlRefused) while an instruction drives the robot: stop it first.
    """
    return teleop_with(teleop_grant(robot, user), user, linear, angular)


def audit_teleops(user, changes) -> None:
    """Audit a socket's changes of teleop commands in one write: (robot name, at, v, w) each."""
    audit.record_many(user, "teleop", [(name, at, {"linear": v, "angular": w}) for name, at, v, w in changes])


def _audit_teleop(user, grant: TeleopGrant, v: float, w: float) -> None:
    """Audit each change of a person's teleop command, not each 5 Hz repeat of a held button.

    The trail still says who drove which robot at what speed from when to when; the repeats would only add
    a database write to every command on the hot path. After HELD_REPEAT_S without a command, the next one
    is a new press and audited again.
    """
    key = f"teleop:last:{grant.robot_id}:{getattr(user, 'pk', None)}"
    if cache.get(key) != [v, w]:
        audit.record(user, "teleop", grant.robot_name, linear=v, angular=w)
    cache.set(key, [v, w], timeout=HELD_REPEAT_S)
