"""WebSockets: one per page. Authenticate by the session, join groups, send the snapshot, then forward deltas.

Close codes: 4401 not logged in, 4403 not allowed to view, 4404 no such robot.
Commands from the browser (stop, teleop) are checked here against the user's role and the robot's lease
exactly as the pages' POST views check them (both call ``run_command``).
"""

import logging
import math

from channels.consumer import get_handler_name
from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncJsonWebsocketConsumer

import live
from access.roles import can_control
from execution import fast_stop
from execution.held_teleop import HeldTeleop
from portal import snapshots

VIEW_PERM = "robots.view_robot"
log = logging.getLogger(__name__)


class CommandError(Exception):
    """A command that is refused or malformed; the message says why, in words."""


def _int_list(ids) -> list[int]:
    if not isinstance(ids, list) or not all(isinstance(pk, int) for pk in ids):
        raise CommandError('robots: give "all" or a list of robot ids')
    return ids


def _number(content: dict, field: str) -> float:
    value = content.get(field, 0.0)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CommandError(f"{field}: must be a number")
    return float(value)


def _control():
    from execution import control  # looked up at each call (the tests put a recorder in its place)

    return control


def _call(action, *args):
    """Run a control action; whatever it refuses or fails with becomes an answer for the person."""
    try:
        return action(*args)
    except Exception as exc:  # a refusal, an unbound topic, a link that is down: all said in words
        log.warning("command %s refused or failed: %s", getattr(action, "__name__", action), exc)
        raise CommandError(str(exc) or exc.__class__.__name__) from exc


def command_stop(user, content: dict) -> str:
    """Stop the robots named (or all), held by someone else or not: a stop always gets through."""
    from robots.models import Robot

    if not can_control(user):
        raise CommandError(f"{user.username} may only view robots, not command them.")
    ids = content.get("robots", "all")
    robots = list(Robot.objects.all() if ids == "all" else Robot.objects.filter(pk__in=_int_list(ids)))
    results = _call(_control().stop, robots, user) if robots else {}
    unreached = [f"{name}: {result}" for name, result in (results or {}).items() if result != "stopped"]
    stopped = ", ".join(robot.name for robot in robots) or "no robot"
    return f"Stopped {stopped}." + "".join(f" {reason}" for reason in unreached)


def teleop_checks(user, content: dict):
    """The checks of a teleop command (role, lease, running instruction, move topic): its grant, or why not."""
    robot_id = content.get("robot")
    if not isinstance(robot_id, int) or isinstance(robot_id, bool):
        raise CommandError("robot: no such robot")
    grant = _control().teleop_grants([robot_id], user)[robot_id]
    if isinstance(grant, Exception):
        log.warning("teleop refused: %s", grant)
        raise _refusal(grant)
    return grant


def _refusal(exc: Exception) -> CommandError:
    """A refusal of control.teleop_grants in the person's words."""
    return CommandError("robot: no such robot" if isinstance(exc, ValueError) else str(exc))


def command_teleop(user, content: dict) -> str:
    """Drive one robot at (linear, angular), clamped to its limits, if the user may command it."""
    linear, angular = _number(content, "linear"), _number(content, "angular")
    grant = teleop_checks(user, content)
    v, w = _call(_control().teleop_with, grant, user, linear, angular)
    return f"{grant.robot_name}: linear {v:.2f} m/s, angular {w:.2f} rad/s"


def checked_teleops(user, robot_ids) -> dict:
    """The checks of several presses at once, for a socket's held buttons: {robot id: grant, or why not}.

    Refusals are audited as run_command audits them.
    """
    grants = _control().teleop_grants(robot_ids, user)
    for robot_id, grant in grants.items():
        if isinstance(grant, Exception):
            grants[robot_id] = _refusal(grant)
            refused(user, "teleop", grants[robot_id])
    return grants


COMMANDS = {"stop": command_stop, "teleop": command_teleop}


def refused(user, name, exc: CommandError) -> None:
    from audit import records as audit

    audit.record(user, "command.refused", name, reason=str(exc))


def run_command(user, content) -> dict:
    """Run one browser command; the reply says whether it was done and why not."""
    name = content.get("command") if isinstance(content, dict) else None
    handler = COMMANDS.get(name)
    reply = {"type": "command.result", "command": name, "ref": content.get("ref") if name else None}
    if handler is None:
        return {**reply, "ok": False, "detail": f"command: unknown, expected one of {sorted(COMMANDS)}"}
    try:
        detail = handler(user, content)
    except CommandError as exc:
        refused(user, name, exc)
        return {**reply, "ok": False, "detail": str(exc)}
    return {**reply, "ok": True, "detail": detail}


class _PageConsumer(AsyncJsonWebsocketConsumer):
    """Authenticate, join the page's groups, send the snapshot first, then forward every delta."""

    async def connect(self):
        await self.accept()
        user = self.scope.get("user")
        if user is None or not user.is_authenticated:
            await self.close(code=4401)
            return
        if not await database_sync_to_async(user.has_perm)(VIEW_PERM):
            await self.close(code=4403)
            return
        snapshot = await database_sync_to_async(self.snapshot)()
        if snapshot is None:
            await self.close(code=4404)
            return
        self.may_control = await database_sync_to_async(can_control)(user)
        if self.may_control:
            fast_stop.TARGETS.refresh()  # what a stop from this page needs, loaded before it is pressed
        self.joined = self.group_names()
        for group in self.joined:
            await self.channel_layer.group_add(group, self.channel_name)
        await self.send_json(snapshot)

    async def dispatch(self, message):
        """Channels' dispatch without its per-message close_old_connections, a hop to the one shared sync
        thread for every frame and push. This consumer reaches the database only through
        database_sync_to_async, whose thread closes old connections around each call itself."""
        handler = getattr(self, get_handler_name(message), None)
        if handler is None:
            raise ValueError(f"No handler for message type {message['type']}")
        await handler(message)

    async def disconnect(self, code):
        if getattr(self, "teleop", None) is not None:
            self.teleop.close()
        for group in getattr(self, "joined", ()):
            await self.channel_layer.group_discard(group, self.channel_name)

    async def receive_json(self, content, **kwargs):
        user = self.scope["user"]
        if not user.is_authenticated:
            return
        if isinstance(content, dict) and content.get("command") == "teleop":
            await self.take_teleop(user, content)
            return
        if (
            isinstance(content, dict)
            and content.get("command") == "stop"
            and getattr(self, "may_control", False)
        ):
            ids = content.get("robots", "all")
            if ids == "all" or (isinstance(ids, list) and all(isinstance(pk, int) for pk in ids)):
                await fast_stop.stop_now(ids)  # a head start; run_command below checks, stops again, answers
        # Not thread-sensitive: one socket's commands do not wait behind every other socket's.
        reply = await database_sync_to_async(run_command, thread_sensitive=False)(user, content)
        await self.send_json(reply)

    async def take_teleop(self, user, content) -> None:
        """Held buttons: checked once per press, repeats published from this loop (execution.held_teleop)."""
        try:
            linear, angular = _number(content, "linear"), _number(content, "angular")
        except CommandError as exc:
            reply = {"type": "command.result", "command": "teleop", "ref": content.get("ref")}
            await self.send_json({**reply, "ok": False, "detail": str(exc)})
            return
        if getattr(self, "teleop", None) is None:
            self.teleop = HeldTeleop(user, self.send_json, checked_teleops, _control())
        self.teleop.take(content, linear, angular)

    async def changed(self, event):
        """A robot's lease or state changed: forward it, and re-check its teleop before the next repeat."""
        if getattr(self, "teleop", None) is not None:
            self.teleop.drop(event.get("id"))
        await self.send_json(event)

    async def forward(self, event):
        await self.send_json(event)

    # One handler per payload type of live; the name matches the message "type".
    robot_status = instruction_update = robot_goal = robot_path = forward
    robot_transition = lease_update = changed

    async def registration_progress(self, event):
        if event.get("ok") and getattr(self, "may_control", False):
            fast_stop.TARGETS.refresh(now=True)  # new robots: a stop from this page reaches them at once
        await self.send_json(event)


class FleetConsumer(_PageConsumer):
    """/ws/fleet/: every robot, every instruction, all poses."""

    def group_names(self):
        return [live.FLEET_GROUP, live.POSES_GROUP]

    def snapshot(self):
        return snapshots.fleet_snapshot()

    async def fleet_poses(self, event):
        await self.send_json(event)


class RobotConsumer(_PageConsumer):
    """/ws/robots/<id>/: one robot's status, transitions, lease, goal and pose."""

    def group_names(self):
        return [live.robot_group(self.robot_id), live.POSES_GROUP]

    def snapshot(self):
        from robots.models import Robot

        self.robot_id = self.scope["url_route"]["kwargs"]["robot_id"]
        robot = Robot.objects.filter(pk=self.robot_id).first()
        return snapshots.robot_snapshot(robot) if robot else None

    async def fleet_poses(self, event):
        mine = [pose for pose in event["poses"] if pose["id"] == self.robot_id]
        if mine:
            await self.send_json({"type": "robots.poses", "poses": mine})
