"""WebSockets: one per page. Authenticate by the session, join groups, send the snapshot, then forward deltas.

Close codes: 4401 not logged in, 4403 not allowed to view, 4404 no such robot.
Commands from the browser (stop, teleop) are checked here against the user's role and the robot's lease
exactly as the pages' POST views check them (both call ``run_command``).
"""

import asyncio
import logging
import math
from typing import NamedTuple

from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncJsonWebsocketConsumer

from fleet import live

VIEW_PERM = "robots.view_robot"
log = logging.getLogger(__name__)


class CommandError(Exception):
    """A command that is refused or malformed; the message says why, in words."""


class CommandDone(NamedTuple):
    """A command's words for the person, and the teleop grant its repeats may reuse."""

    detail: str
    grant: object


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
    try:
        from fleet import control
    except ImportError as exc:
        raise CommandError("robot control is not available on this server yet") from exc
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
    from fleet.roles import can_control
    from robots.models import Robot

    if not can_control(user):
        raise CommandError(f"{user.username} may only view robots, not command them.")
    ids = content.get("robots", "all")
    robots = list(Robot.objects.all() if ids == "all" else Robot.objects.filter(pk__in=_int_list(ids)))
    results = _call(_control().stop, robots, user) if robots else {}
    unreached = [f"{name}: {result}" for name, result in (results or {}).items() if result != "stopped"]
    stopped = ", ".join(robot.name for robot in robots) or "no robot"
    return f"Stopped {stopped}." + "".join(f" {reason}" for reason in unreached)


def command_teleop(user, content: dict) -> str:
    """Drive one robot at (linear, angular), clamped to its limits, if the user may command it."""
    from fleet.leases import ControlRefused, check_command
    from robots.models import Robot

    robot = (
        Robot.objects.filter(pk=content.get("robot")).first()
        if isinstance(content.get("robot"), int)
        else None
    )
    if robot is None:
        raise CommandError("robot: no such robot")
    linear = max(-robot.max_linear, min(robot.max_linear, _number(content, "linear")))
    angular = max(-robot.max_angular, min(robot.max_angular, _number(content, "angular")))
    try:
        check_command(user, robot)
    except ControlRefused as exc:
        raise CommandError(str(exc)) from exc
    control = _control()
    grant = _call(control.teleop_grant, robot, user)
    _call(control.teleop_with, grant, user, linear, angular)
    return CommandDone(f"{robot.name}: linear {linear:.2f} m/s, angular {angular:.2f} rad/s", grant)


COMMANDS = {"stop": command_stop, "teleop": command_teleop}


def run_command(user, content, with_grant: bool = False) -> dict:
    """Run one browser command; the reply says whether it was done and why not.

    with_grant: a teleop's reply carries its grant under "grant" (the socket keeps it; never sent on).
    """
    name = content.get("command") if isinstance(content, dict) else None
    handler = COMMANDS.get(name)
    reply = {"type": "command.result", "command": name, "ref": content.get("ref") if name else None}
    if handler is None:
        return {**reply, "ok": False, "detail": f"command: unknown, expected one of {sorted(COMMANDS)}"}
    try:
        detail = handler(user, content)
    except CommandError as exc:
        from fleet import audit

        audit.record(user, "command.refused", name, reason=str(exc))
        return {**reply, "ok": False, "detail": str(exc)}
    if isinstance(detail, CommandDone):
        grant = {"grant": detail.grant} if with_grant else {}
        return {**reply, "ok": True, "detail": detail.detail, **grant}
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
        self.joined = self.group_names()
        for group in self.joined:
            await self.channel_layer.group_add(group, self.channel_name)
        await self.send_json(snapshot)

    async def disconnect(self, code):
        for task in getattr(self, "chains", {}).values():
            task.cancel()  # a held button's last repeats: the socket that wanted them is gone
        for group in getattr(self, "joined", ()):
            await self.channel_layer.group_discard(group, self.channel_name)

    async def receive_json(self, content, **kwargs):
        user = self.scope["user"]
        if not user.is_authenticated:
            return
        if self.held_teleop_in_order(user, content):
            return
        # Not thread-sensitive: one socket's commands do not wait behind every other socket's.
        command = database_sync_to_async(run_command, thread_sensitive=False)
        reply = await command(user, content, with_grant=True)
        self.remember_grant(reply)
        await self.send_json(reply)

    def held_teleop_in_order(self, user, content) -> bool:
        """Take a held button's repeat under this socket's fresh grant, without the database.

        Robots are driven side by side (a message for one robot does not wait for another's publish), and
        each robot's commands still go out in the order they came. False: the command goes the full way.
        """
        if not (isinstance(content, dict) and content.get("command") == "teleop"):
            return False
        grant = getattr(self, "grants", {}).get(content.get("robot"))
        if grant is None or not grant.valid:
            return False
        try:
            linear, angular = _number(content, "linear"), _number(content, "angular")
        except CommandError:
            return False
        chains = self.__dict__.setdefault("chains", {})
        previous = chains.get(grant.robot_id)
        chains[grant.robot_id] = asyncio.ensure_future(
            self.held_teleop(previous, grant, user, linear, angular, content.get("ref"))
        )
        return True

    async def held_teleop(self, previous, grant, user, linear, angular, ref) -> None:
        if previous is not None:
            await asyncio.gather(previous, return_exceptions=True)
        reply = {"type": "command.result", "command": "teleop", "ref": ref}
        try:
            teleop_with = database_sync_to_async(_control().teleop_with, thread_sensitive=False)
            v, w = await teleop_with(grant, user, linear, angular)
        except Exception as exc:  # the link went down under the grant: said in words, grant dropped
            self.grants.pop(grant.robot_id, None)
            await self.send_json({**reply, "ok": False, "detail": str(exc) or type(exc).__name__})
            return
        detail = f"{grant.robot_name}: linear {v:.2f} m/s, angular {w:.2f} rad/s"
        await self.send_json({**reply, "ok": True, "detail": detail})

    def remember_grant(self, reply) -> None:
        """After a teleop went the full way and was allowed, keep its grant for the repeats."""
        grant = reply.pop("grant", None)
        if grant is not None:
            self.grants = {**getattr(self, "grants", {}), grant.robot_id: grant}

    async def forward(self, event):
        await self.send_json(event)

    # One handler per payload type of fleet.live; the name matches the message "type".
    robot_status = robot_transition = instruction_update = lease_update = robot_goal = forward
    registration_progress = forward


class FleetConsumer(_PageConsumer):
    """/ws/fleet/: every robot, every instruction, all poses."""

    def group_names(self):
        return [live.FLEET_GROUP, live.POSES_GROUP]

    def snapshot(self):
        return live.fleet_snapshot()

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
        return live.robot_snapshot(robot) if robot else None

    async def fleet_poses(self, event):
        mine = [pose for pose in event["poses"] if pose["id"] == self.robot_id]
        if mine:
            await self.send_json({"type": "fleet.poses", "poses": mine})
