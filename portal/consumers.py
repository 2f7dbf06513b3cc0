"""WebSockets: one per page. Authenticate by the session, join groups, send the snapshot, then forward deltas.

Close codes: 4401 not logged in, 4403 not allowed to view, 4404 no such robot.
Commands from the browser (stop, teleop) are checked here against the role matrix (access.roles: ``COMMANDS``
names each command's ability) and the robot's lease exactly as the pages' POST views check them (both call
``run_command``). What a browser sends is decoded and rate-limited by portal.socket_input; every malformed,
unknown, refused or dropped message is answered with a ``command.result`` saying why, never a traceback.
"""

import asyncio
import contextlib
import logging
import math
from dataclasses import dataclass

from channels.consumer import get_handler_name
from channels.db import database_sync_to_async
from channels.exceptions import StopConsumer
from channels.generic.websocket import AsyncJsonWebsocketConsumer
from channels.layers import get_channel_layer
from django.db import DatabaseError

import live
from access.leases import ControlRefused
from access.roles import may, refusal
from audit import records as audit
from execution import fast_stop
from execution.held_teleop import HeldTeleop
from execution.instructions import Reading, submit, understand
from execution.link import LinkError
from execution.models import Instruction
from fleetcore import jsontext
from interpreter.service import warm_up
from portal import feeds, inspector, snapshots, socket_input
from portal.fanout import EventFanout, PoseFanout
from portal.schemas import InstructionOut
from portal.socket_input import BadFrame
from robots.commands import ROW_FIELDS
from robots.models import Robot
from robots.rosbridge.errors import RosbridgeError

log = logging.getLogger(__name__)
_FINISHING: set[asyncio.Task] = set()  # commands' bookkeeping running beside their sockets' frames
UNDERSTOOD = "_understood"  # the socket's Reading of an instruct message's text, handed on to submit


def _finished(task: asyncio.Task) -> None:
    _FINISHING.discard(task)
    if not task.cancelled() and task.exception() is not None:
        log.error("a command's bookkeeping failed", exc_info=task.exception())


class CommandError(Exception):
    """A command that is refused or malformed; the message says why, in words."""


def _number(content: dict, field: str) -> float:
    value = content.get(field, 0.0)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CommandError(f"{field}: must be a number")
    return float(value)


def _control():
    from execution import control  # looked up at each call (the tests put a recorder in its place)

    return control


def _in_words(exc: Exception) -> str:
    """What a person reads about a failure: refusals and link errors as they are; the database and anything
    unexpected in general words (the log keeps the details), so no raw SQL error reaches a page."""
    if isinstance(exc, DatabaseError):
        return "the database is busy or unavailable; try again in a moment"
    if isinstance(
        exc, CommandError | ValueError | LookupError | PermissionError | ConnectionError | TimeoutError
    ):
        return str(exc) or exc.__class__.__name__
    if isinstance(exc, ControlRefused | LinkError | RosbridgeError):
        return str(exc) or exc.__class__.__name__
    return f"could not be done: an internal error ({exc.__class__.__name__}), logged for the admins"


def _call(action, *args):
    """Run a control action; whatever it refuses or fails with becomes an answer for the person."""
    try:
        return action(*args)
    except Exception as exc:  # a refusal, an unbound topic, a link that is down: all said in words
        log.warning("command %s refused or failed: %r", getattr(action, "__name__", action), exc)
        raise CommandError(_in_words(exc)) from exc


def command_stop(user, content: dict) -> str:
    """Stop the robots named (or all), held by someone else or not: a stop always gets through."""
    try:
        ids = socket_input.robot_ids(content.get("robots", "all"))
    except BadFrame as exc:
        raise CommandError(str(exc)) from None
    # only what the zeros read (no JSON column: a fleet's footprints and URDF facts were a fifth of a stop-all's time)
    robots = list(
        (Robot.objects.all() if ids == "all" else Robot.objects.filter(pk__in=ids)).only(*ROW_FIELDS)
    )
    results = _call(_control().stop, robots, user) if robots else {}
    unreached = [f"{name}: {result}" for name, result in (results or {}).items() if result != "stopped"]
    stopped = ", ".join(robot.name for robot in robots) or "no robot"
    note = results.note() if hasattr(results, "note") else ""  # what of the bookkeeping failed, said
    return f"Stopped {stopped}." + "".join(f" {reason}" for reason in unreached) + note


def teleop_checks(user, content: dict):
    """The checks of a teleop command (role, lease, running instruction, move topic): its grant, or why not."""
    try:
        robot_id = socket_input.robot_id(content.get("robot"))
    except BadFrame as exc:
        raise CommandError(str(exc)) from None
    grant = _call(_control().teleop_grants, [robot_id], user)[robot_id]
    if isinstance(grant, Exception):
        log.warning("teleop refused: %s", grant)
        raise _refusal(grant)
    return grant


def _refusal(exc: Exception) -> CommandError:
    """A refusal of control.teleop_grants in the person's words."""
    return CommandError("robot: no such robot" if isinstance(exc, ValueError) else _in_words(exc))


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
    try:
        grants = _control().teleop_grants(robot_ids, user)
    except DatabaseError as exc:  # said in general words: no raw database error reaches the page
        log.warning("teleop checks failed: %r", exc)
        return dict.fromkeys(robot_ids, CommandError(_in_words(exc)))
    for robot_id, grant in grants.items():
        if isinstance(grant, Exception):
            grants[robot_id] = _refusal(grant)
            refused(user, "teleop", grants[robot_id])
    return grants


def command_instruct(user, content: dict) -> tuple[str, dict]:
    """An instruction typed in the console, sent over the page's socket: the answer carries the instruction."""
    text, answer_to = content.get("text"), content.get("answer_to")
    if not isinstance(text, str) or not text.strip() or len(text) > 2000 or "\x00" in text:
        raise CommandError("text: an instruction of 1 to 2000 characters")
    question = None
    if answer_to is not None:
        try:
            question = Instruction.objects.get(pk=socket_input.robot_id(answer_to), status="needs_user")
        except (BadFrame, Instruction.DoesNotExist):
            raise CommandError("answer_to: no question waits for an answer with that id") from None
    # The robots selected on the page: a text that names none goes to them.
    selected = content.get("robot_ids")
    try:
        selected = socket_input.robot_ids(selected) if selected else None
    except BadFrame as exc:
        raise CommandError(f"robot_ids: {exc}") from None
    if selected == "all":
        raise CommandError("robot_ids: a list of robot ids")
    reading = content.get(UNDERSTOOD)  # the socket's reading of this text (never from a browser's frame)
    reading = reading if isinstance(reading, Reading) else None
    instruction = _call(submit, text, user, "console", reading, question, selected)
    return f"#{instruction.pk} {instruction.status}", {"instruction": InstructionOut.of(instruction)}


@dataclass(frozen=True)
class Command:
    """One message type a page may send: its handler and the ability (access.roles.ABILITIES) it needs."""

    handler: object
    ability: str


COMMANDS = {
    "stop": Command(command_stop, "control"),
    "teleop": Command(command_teleop, "control"),
    "instruct": Command(command_instruct, "instruct"),
}


def refused(user, name, exc: CommandError) -> None:
    audit.record(user, "command.refused", str(name)[:40], reason=str(exc))


def result(content, ok: bool, detail: str, **extra) -> dict:
    """The answer to one message: which command, the browser's ref, whether it was done, and why not."""
    name = content.get("command") if isinstance(content, dict) else None
    ref = content.get("ref") if isinstance(content, dict) else None
    name = name if isinstance(name, str) and len(name) <= 40 else None
    ref = ref if isinstance(ref, str | int) and not isinstance(ref, bool) and len(str(ref)) <= 100 else None
    return {"type": "command.result", "command": name, "ref": ref, "ok": ok, "detail": detail, **extra}


def run_command(user, content) -> dict:
    """Run one browser command; the reply says whether it was done and why not."""
    name = content.get("command") if isinstance(content, dict) else None
    command = COMMANDS.get(name) if isinstance(name, str) else None
    if command is None:
        return result(content, False, f"command: unknown, expected one of {sorted(COMMANDS)}")
    try:
        if not may(user, command.ability):
            raise CommandError(refusal(user, command.ability))
        detail, extra = _with_extra(command.handler(user, content))
    except CommandError as exc:
        refused(user, name, exc)
        return result(content, False, str(exc))
    except Exception as exc:  # a bug or the database: said in words, kept in the log
        log.exception("command %s failed", name)
        return result(content, False, _in_words(exc))
    return result(content, True, detail, **extra)


def _with_extra(answer) -> tuple[str, dict]:
    """A handler answers in words, or in words with data for the page."""
    return answer if isinstance(answer, tuple) else (answer, {})


async def _accept_user(consumer) -> object | None:
    """Accept the socket and return its logged-in user; close it with 4401 (not logged in) and return None."""
    await consumer.accept()
    user = consumer.scope.get("user")
    if user is None or not user.is_authenticated:
        await consumer.close(code=4401)
        return None
    return user


class _StrictJson(AsyncJsonWebsocketConsumer):
    """Sends strict JSON only: a bare NaN or Infinity would make JSON.parse throw in every browser reading it
    (fleetcore.jsontext.dumps writes them as null; `json` with allow_nan=False raised, and the push was lost)."""

    @classmethod
    async def encode_json(cls, content):
        return jsontext.dumps(content)

    _frame: list | None = None  # while dispatch_many runs: what the handlers send, to go as one frame

    async def __call__(self, scope, receive, send):
        """Channels' AsyncConsumer.__call__ without a channel of the socket's own: every push reaches a page
        socket through its process's group readers (portal.fanout), never through a channel of its own, so each
        socket's waiting receive on one (and channels' asyncio.wait over the two, a task and three turns of the
        loop for every frame) was cost for nothing: a frame from the page is now read with one await and
        dispatched, one at a time as before."""
        self.scope = scope
        self.channel_layer = get_channel_layer(self.channel_layer_alias)  # the group readers' layer
        self.base_send = send
        with contextlib.suppress(StopConsumer):
            while True:
                await self.dispatch(await receive())

    async def dispatch(self, message):
        """Channels' dispatch without its per-message close_old_connections, a hop to the one shared sync
        thread for every frame and push. This consumer reaches the database only through
        database_sync_to_async, whose thread closes old connections around each call itself. A page's frame (a
        held button's command five times a second) goes straight to receive, as websocket_receive would."""
        if message["type"] == "websocket.receive":
            await self.receive(text_data=message.get("text"), bytes_data=message.get("bytes"))
            return
        handler = getattr(self, get_handler_name(message), None)
        if handler is None:
            raise ValueError(f"No handler for message type {message['type']}")
        await handler(message)

    async def dispatch_many(self, messages: list[dict]) -> None:
        """Pushes that came together (portal.fanout's burst): each handled as dispatch() would, and what they
        send goes to the page as one {"type": "batch", "messages": [...]} frame, in their order."""
        self._frame = []
        try:
            for message in messages:
                try:
                    await self.dispatch(message)
                except Exception:  # one handler's failure costs its message only
                    log.exception("a %r push failed on one socket", message.get("type"))
        finally:
            frame, self._frame = self._frame, None
        if frame:
            await self.send_json(live.page_frame(frame))

    async def send_json(self, content, close=False):
        if self._frame is not None and not close:
            self._frame.append(content)  # a burst's frame is being gathered (dispatch_many)
            return
        await super().send_json(content, close)


class _PageConsumer(_StrictJson):
    """Authenticate, join the page's groups, send the snapshot first, then forward every delta."""

    async def connect(self):
        user = await _accept_user(self)
        if user is None:
            return
        self.abilities = await database_sync_to_async(self.granted)(user)
        if not self.abilities["view"]:
            await self.close(code=4403)
            return
        if not self.known():
            await self.close(code=4404)
            return
        # subscribed before the snapshot is read: a change made while it is read (or while this connect warms up)
        # reaches the page after it, in order; read first, such a change was never sent to this page, which showed
        # the state the snapshot had until the robot changed again
        self.joined = [EventFanout.of(self.channel_layer, group) for group in self.group_names()]
        for events in self.joined:  # the process's one reader of each group (portal.fanout)
            await events.subscribe(self)
        for events in self.joined:  # a process's first page: its readers are joining the groups (bounded)
            await events.joined()
        snapshot = await database_sync_to_async(self.snapshot)()
        if snapshot is None:
            await self.close(code=4404)
            return
        self.may_control = self.abilities["control"]
        self.limiter = socket_input.RateLimiter()
        self.stops_running: set[asyncio.Task] = set()  # this page's stops whose bookkeeping is under way
        if self.may_control:
            fast_stop.TARGETS.refresh()  # what a stop from this page needs, loaded before it is pressed
        if self.abilities["instruct"]:
            await database_sync_to_async(
                warm_up, thread_sensitive=False
            )()  # a first typed stop waits for no ontology
        await self.send_json(snapshot)
        for events in self.joined:  # what came meanwhile follows the snapshot
            events.release(self)
        self.poses = PoseFanout.of(self.channel_layer)  # the ticks of poses after the snapshot, from the
        await self.poses.subscribe(self, self.poses_of())  # process's one reader (portal.fanout)

    def poses_of(self) -> int | None:
        """The robot whose poses this page shows; None for all."""
        return None

    def known(self) -> bool:
        """Whether the page's address can name something (read from it, and checked, before any group is joined
        for it)."""
        return True

    @staticmethod
    def granted(user) -> dict[str, bool]:
        """The abilities a socket's commands need, asked once at connect."""
        return {name: may(user, name) for name in {"view", *(c.ability for c in COMMANDS.values())}}

    async def disconnect(self, code):
        if getattr(self, "teleop", None) is not None:
            self.teleop.close()
        if getattr(self, "feeds", None) is not None:
            await self.feeds.close()
        try:
            if getattr(self, "poses", None) is not None:
                await self.poses.unsubscribe(self)
            for events in getattr(self, "joined", ()):
                await events.unsubscribe(self)
        except Exception as exc:  # Redis frozen or refusing writes: the groups' entries expire on their own
            log.warning("socket closed without leaving its groups: %r", exc)

    async def receive(self, text_data=None, bytes_data=None, **kwargs):
        """Every frame: decoded and rate-limited (portal.socket_input), then one command; bad ones answered."""
        if getattr(self, "limiter", None) is None:
            return  # closed at connect (not logged in, not allowed): nothing is read
        try:
            content = socket_input.decode(text_data, bytes_data)
        except BadFrame as exc:
            await self.refuse({}, str(exc), key=("frame",))
            return
        key = socket_input.rate_key(content)
        if not self.limiter.allow(key):
            if self.limiter.warn(key):
                await self.refuse(content, f"rate: more than {self.limiter.rate:g} {key[0]} messages a second; "
                                  "the extra ones were dropped")  # fmt: skip
            return
        await self.receive_json(content)

    async def refuse(self, content, detail: str, key=None) -> None:
        """Answer a message that was not run; malformed frames are rate-limited like any other."""
        if key is not None and not self.limiter.allow(key):
            return
        await self.send_json(result(content, False, detail))

    async def receive_json(self, content, **kwargs):
        user = self.scope["user"]
        if content.get("command") == "watch":
            await self.watch(content)
            return
        if content.get("command") == "teleop" and self.abilities["control"]:
            await self.take_teleop(user, content)
            return
        if content.get("command") == "stop" and self.abilities["control"]:
            try:
                ids = socket_input.robot_ids(content.get("robots", "all"))
            except BadFrame as exc:
                await self.refuse(content, str(exc))
                return
            await fast_stop.stop_now(ids)  # a head start; run_command checks, stops again, answers
            self.stopping(user, content, ids)
            return
        if content.get("command") == "instruct" and self.abilities["instruct"]:
            content, stopped = await self.typed_stop_head_start(content)
            if stopped is not None:  # a typed stop, its zeros out: stored (submit) as a STOP's bookkeeping is
                self.stopping(user, content, stopped)
                return
        if self.stops_running:  # what the page sent after a stop comes after it: never cancelled by it
            await asyncio.gather(*self.stops_running, return_exceptions=True)
        await self.run_and_answer(user, content)

    async def run_and_answer(self, user, content) -> None:
        """Run the command (control's checks, in a thread) and answer it on the socket."""
        # Not thread-sensitive: one socket's commands do not wait behind every other socket's.
        reply = await database_sync_to_async(run_command, thread_sensitive=False)(user, content)
        try:
            await self.send_json(reply)
        except OSError as exc:  # the page went away meanwhile (uvicorn's ClientDisconnected): it was run
            log.debug("a command's answer found its page gone: %r", exc)

    def stopping(self, user, content, robot_ids) -> None:
        """A stop's bookkeeping (flags, second zeros, queues, leases, audit; a typed stop's instruction too) beside
        the socket's frames, its zeros already out: it takes seconds for a large fleet, and the page's next frame,
        a STOP above all, must not wait behind it. What the page sends next, but a stop, waits for it."""
        self.stops_running.add(task := self.finishing(self.run_and_answer(user, content)))
        task.add_done_callback(self.stops_running.discard)
        if getattr(self, "teleop", None) is not None:
            self.teleop.stopped(robot_ids, task)  # no press read before the stop goes out after its zero

    def finishing(self, work) -> asyncio.Task:
        """Run work beside the socket's frames, kept until it ends (a closed page does not cut it short)."""
        task = asyncio.ensure_future(work)
        _FINISHING.add(task)
        task.add_done_callback(_finished)
        return task

    async def typed_stop_head_start(self, content: dict) -> tuple[dict, list[int] | str | None]:
        """The typed text read once: a "stop ..." gets flags and zeros from this loop, as the STOP button's, before
        submit writes anything. Returns the message with what was understood (submit does not read it again) and,
        for a stop, the robots it stops (ids, or "all"); None for anything else."""
        text = content.get("text")
        if not isinstance(text, str) or not text.strip() or len(text) > 2000:
            return content, None  # command_instruct refuses it in words
        try:
            reading = await database_sync_to_async(understand, thread_sensitive=False)(text)
        except (
            Exception
        ):  # the database or the ontology: submit reads it again and says what failed, in words
            log.exception("reading %r for a stop's head start failed", text[:80])
            return content, None
        stopped = None
        if reading.stops is not None:
            stopped = fast_stop.TARGETS.ids(reading.stops)
            await fast_stop.stop_now(stopped)
        return {**content, UNDERSTOOD: reading}, stopped

    async def watch(self, content) -> None:
        """Follow one robot's scan on this page's map ({"command": "watch", "robot": id or null})."""
        robot = content.get("robot")
        try:
            robot_id = None if robot is None else socket_input.robot_id(robot)
        except BadFrame as exc:
            await self.refuse(content, str(exc))
            return
        if getattr(self, "feeds", None) is None:
            self.feeds = feeds.Feeds(self.send_json)
        await self.feeds.watch(robot_id, ("scan",))

    async def take_teleop(self, user, content) -> None:
        """Held buttons: checked once per press, repeats published from this loop (execution.held_teleop)."""
        try:
            socket_input.robot_id(content.get("robot"))
            linear, angular = _number(content, "linear"), _number(content, "angular")
        except (BadFrame, CommandError) as exc:
            await self.refuse(content, str(exc))
            return
        if getattr(self, "teleop", None) is None:
            self.teleop = HeldTeleop(user, self.send_json, checked_teleops, _control(), self.stops_running)
        await self.teleop.take(content, linear, angular)

    async def changed(self, event):
        """A robot's lease or state changed: forward it, and re-check its teleop before the next repeat."""
        if getattr(self, "teleop", None) is not None:
            self.teleop.drop(event.get("id"))
        await self.send_json(event)

    async def forward(self, event):
        await self.send_json(event)

    # One handler per payload type of live; the name matches the message "type".
    robot_status = instruction_update = robot_goal = robot_path = robot_queue = forward
    robot_transition = lease_update = changed

    async def registration_progress(self, event):
        if event.get("ok") and getattr(self, "may_control", False):
            fast_stop.TARGETS.refresh(now=True)  # new robots: a stop from this page reaches them at once
        await self.send_json(event)


class FleetConsumer(_PageConsumer):
    """/ws/fleet/: every robot, every instruction, all poses."""

    def group_names(self):
        return [live.FLEET_GROUP]

    def snapshot(self):
        return snapshots.fleet_snapshot()


class RobotConsumer(_PageConsumer):
    """/ws/robots/<id>/: one robot's status, transitions, lease, goal and pose."""

    def known(self) -> bool:
        self.robot_id = self.scope["url_route"]["kwargs"]["robot_id"]
        return 1 <= self.robot_id <= socket_input.MAX_ID

    def group_names(self):
        return [live.robot_group(self.robot_id)]

    def poses_of(self) -> int | None:
        return self.robot_id

    def snapshot(self):
        robot = Robot.objects.filter(pk=self.robot_id).first()
        return snapshots.robot_snapshot(robot) if robot else None

    async def receive_json(self, content, **kwargs):
        """The topic inspector ({"command": "inspect", "topic": "/odom"}; no topic: off) for whoever may look at
        the robot; every other command as on any page."""
        if content.get("command") != "inspect":
            await super().receive_json(content, **kwargs)
            return
        if getattr(self, "inspector", None) is None:
            self.inspector = inspector.Inspector(self.robot_id, self.send_json)
        try:
            detail = await self.inspector.inspect(content.get("topic"))
        except inspector.NotInspectable as exc:
            await self.send_json(result(content, False, str(exc)))
            return
        await self.send_json(result(content, True, detail))

    async def disconnect(self, code):
        if getattr(self, "inspector", None) is not None:
            await self.inspector.close()
        await super().disconnect(code)

    async def connect(self):
        await super().connect()
        if getattr(
            self, "joined", None
        ):  # accepted: its robot's scan, camera and diagnostics follow while the page is open
            self.feeds = feeds.Feeds(self.send_json)
            try:
                await self.feeds.watch(self.robot_id)
            except Exception:  # a feed that cannot start costs its panel, never the page's socket
                log.exception("robot %s: sensor feeds not started", self.robot_id)


class AlertsConsumer(_StrictJson):
    """/ws/alerts/ on every page: the open alerts first, then each raise, acknowledgement and resolution."""

    async def connect(self):
        user = await _accept_user(self)
        if user is None:
            return
        if not await database_sync_to_async(may)(user, "view_alerts"):
            await self.close(code=4403)
            return
        self.events = EventFanout.of(self.channel_layer, live.ALERTS_GROUP)
        await self.events.subscribe(self)
        await self.send_json(await database_sync_to_async(snapshots.alerts_snapshot)())
        self.events.release(self)

    async def disconnect(self, code):
        if getattr(self, "events", None) is not None:
            await self.events.unsubscribe(self)

    async def alert_update(self, event):
        await self.send_json(event)
