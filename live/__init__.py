"""Every push to browsers goes through here: typed payloads sent to Channels groups after the commit.

Groups: "fleet" (every dashboard), "robot.<pk>" (a robot's page) and "alerts" (every page's alert badge). Consumers only authenticate, join groups
and forward; the handler name in the consumer matches the payload's "type".
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
import weakref
from collections.abc import Iterator
from typing import NotRequired, TypedDict

from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.db import transaction

FLEET_GROUP = "fleet"
ALERTS_GROUP = "alerts"
# What every reader of a group is handed by the channel layer (fleet.channel_layer) once its subscription, cut,
# is taken again: the pushes published in between are lost (portal.fanout sends its pages back to a snapshot).
RESUBSCRIBED = "layer.resubscribed"
log = logging.getLogger(__name__)


def robot_group(robot_id: int) -> str:
    return f"robot.{robot_id}"


class RobotStatus(TypedDict, total=False):
    type: str  # "robot.status"
    robot: str
    id: int
    link_status: str
    state: str
    last_seen: str | None
    stop_hold: str | None  # "held by a stop (admin, 10:43:44)" (Robot.hold_words), None when nothing holds it


class StateChange(TypedDict):
    type: str  # "robot.transition"
    robot: str
    id: int
    from_state: str
    to_state: str
    at: str
    reason: str
    instruction: int | None


class InstructionUpdate(TypedDict, total=False):
    type: str  # "instruction.update"
    id: int
    text: str
    status: str
    outcome: str
    expired: bool  # a question nobody answered in time: the console drops it from Progress
    photos: list[str]  # where to see the photos its robots took (a finished instruction's), oldest first


class QueueEntry(TypedDict):
    instruction: int
    text: str
    user: str | None
    status: str  # running, queued, preempted
    position: int  # 0 for the running one, 1.. for the waiting ones in the order they will run
    step: int | None  # the step it is at ("step 2 of 3")
    steps: int
    doing: str  # that step in words (interpreter.forms.read_back)
    goal: dict | None  # a move's goal {name, x, y}: the page ages distance_left and eta_s with each pose
    distance_left: float | None  # m, straight line from the last pose to a move's goal
    speed: float | None  # m/s, the step's speed word on the robot's limit
    eta_s: float | None  # distance_left / speed


class RobotQueue(TypedDict):
    type: str  # "robot.queue"
    robot: str
    id: int
    running: QueueEntry | None
    queued: list[QueueEntry]


class AlertUpdate(TypedDict):
    type: str  # "alert.update"
    alert: dict  # alerts.service.as_dict: id, kind, severity, robot, message, count, status, who and when
    open_count: int  # alerts open now, for every page's badge


SEND_TIMEOUT_S = 0.5  # a push waits this long at most for Redis (the channel layer)
QUIET_S = 2.0  # after a push failed, the next ones are skipped this long: a frozen Redis costs one wait
_quiet_until = 0.0
_home = threading.local()  # .loop: the event loop this thread's pushes are handed to (deliver_on)
# the outbox of each loop pushes are handed to (deliver_on)
_outboxes: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, Outbox] = weakref.WeakKeyDictionary()


def deliver_on(loop: asyncio.AbstractEventLoop) -> None:
    """Hand this thread's pushes to `loop` (a thread of the executor's blocking pool: its loop's own).

    Without it a push from a plain thread goes through async_to_sync, which runs a new event loop on a new
    thread each time, and the channel layer opens a new Redis connection for that loop: a few milliseconds of
    CPU per push, where the loop's own connection costs a send. Handed over, a push does not wait for Redis."""
    _home.loop = loop


class Outbox:
    """The pushes handed to one event loop (deliver_on), sent in their order by one task at a time: what comes
    while it sends goes in its next round, each group's pushes in one message (_batched). A task per push let an
    executor starting 50 robots have hundreds of channel-layer sends in flight at once: the layer's pool of 100
    connections ran out (MaxConnectionsError) and the loop's time went to them rather than to its robots."""

    def __init__(self) -> None:
        self.pending: list[tuple[str, dict]] = []
        self.sending: asyncio.Task | None = None

    def put(self, group: str, payload: dict) -> None:
        self.pending.append((group, payload))
        if self.sending is None:
            self.sending = asyncio.ensure_future(self._send())

    async def _send(self) -> None:
        try:
            while self.pending:
                pushes, self.pending = self.pending, []
                await _send_each(get_channel_layer(), _batched(pushes))
        finally:
            self.sending = None


def _outbox(group: str, payload: dict) -> None:
    """On the loop's thread: the push into the loop's outbox."""
    loop = asyncio.get_running_loop()
    box = _outboxes.get(loop)
    if box is None:
        box = _outboxes[loop] = Outbox()
    box.put(group, payload)


def send(group: str, payload: dict) -> None:
    """Send now (from sync code outside a transaction, or from a worker loop); never raises.

    A push is best effort: Redis frozen, away or refusing writes is logged and the push lost (pages catch up
    from their next snapshot), so what pushed it (a stop's answer above all) goes on within SEND_TIMEOUT_S.
    """
    layer = get_channel_layer()
    if layer is None or time.monotonic() < _quiet_until:
        return
    gathered = getattr(_home, "gathered", None)
    if gathered is not None:  # inside together(): sent with the others at its end
        gathered.append((group, payload))
        return
    loop = getattr(_home, "loop", None)
    if loop is not None and not loop.is_closed():
        # (RuntimeError: the loop closed meanwhile, and the push is lost, as on a failure)
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(_outbox, group, payload)
        return
    try:
        async_to_sync(_send_bounded)(layer, group, payload)
    except Exception as exc:
        _lost(group, exc)


@contextlib.contextmanager
def together() -> Iterator[None]:
    """The pushes this thread sends in the block go at its end, in their order, in one hand-over. A stop of 100
    robots pushes each robot's status: from a thread with no event loop around it (a Celery task, the CLI, the
    scheduler's watchdog) each went through async_to_sync, a new event loop, thread and Redis connection per push,
    0.8 s of CPU for the stop; from a web server's thread, a hand-over to the server's loop and a wait per push.
    Inside a transaction, what is sent on commit goes then, as before."""
    if getattr(_home, "gathered", None) is not None:  # nested: the outer block sends them
        yield
        return
    _home.gathered = gathered = []
    try:
        yield
    finally:
        _home.gathered = None
        if gathered:
            _send_all(gathered)


def page_frame(messages: list[dict]) -> dict:
    """What goes to a page for messages that go together: the one message, or {"type": "batch", "messages": [...]}
    (a burst of pushes: portal.fanout; a burst of teleop answers: execution.held_teleop), which
    static/fleet/live.js takes apart in their order."""
    return messages[0] if len(messages) == 1 else {"type": "batch", "messages": messages}


def page_messages(frame: dict) -> list[dict]:
    """The messages one frame sent to a page carries (page_frame's inverse), as static/fleet/live.js reads it."""
    return frame["messages"] if frame.get("type") == "batch" else [frame]


BATCH = "live.batch"  # a together() block's pushes to one group, in one channel-layer message: unbatched()
BATCH_MAX = 200  # pushes in one such message at most (a 1,000-robot stop's statuses are five)


def unbatched(message: dict) -> list[dict]:
    """The pushes one message read from a group carries, in their order (every reader of a group unpacks it)."""
    return message["messages"] if message.get("type") == BATCH else [message]


def _by_group(pushes: list[tuple[str, dict]]) -> dict[str, list[dict]]:
    """Each group's payloads in their order, the groups in the order of their first push."""
    by_group: dict[str, list[dict]] = {}
    for group, payload in pushes:
        by_group.setdefault(group, []).append(payload)
    return by_group


def _batched(pushes: list[tuple[str, dict]]) -> list[tuple[str, dict]]:
    """The pushes to each group as one message per BATCH_MAX: a push costs the sender a Redis round trip (a
    PUBLISH; about seven with channels_redis' list layer, used until 2026-11-29) and every reader its decoding
    and handling, whatever its size; a stop of 100 robots pushed 100 statuses to the fleet group (bench.cluster,
    redis-cli MONITOR: most of a web process's Redis commands). Each group's pushes keep their order; there is
    no order between groups (each has its own readers, and a page reads one group)."""
    out = []
    for group, payloads in _by_group(pushes).items():
        for start in range(0, len(payloads), BATCH_MAX):
            chunk = payloads[start : start + BATCH_MAX]
            out.append((group, chunk[0] if len(chunk) == 1 else {"type": BATCH, "messages": chunk}))
    return out


def _send_all(pushes: list[tuple[str, dict]]) -> None:
    """Send these pushes, each group's in one message (_batched), each bounded as send's; on the thread's home
    loop when it has one."""
    pushes = _batched(pushes)
    layer = get_channel_layer()
    loop = getattr(_home, "loop", None)
    if loop is not None and not loop.is_closed():
        for group, payload in pushes:
            send(group, payload)
        return
    try:
        async_to_sync(_send_each)(layer, pushes)
    except Exception as exc:  # not a push's failure (those are logged in _send_each): the loop's own
        _lost(pushes[0][0], exc)


GROUPS_AT_ONCE = 16  # groups a hand-over sends to concurrently


async def _send_each(layer, pushes: list[tuple[str, dict]]) -> None:
    """Each group's messages in their order, up to GROUPS_AT_ONCE groups at a time: a page reads one group, so
    no page sees an order between groups. One after the other, an instruction to 50 robots (the fleet's group and
    each robot's page group: 51 group_sends of a Redis round trip or more each) held its POST's answer 60 ms on
    an idle cluster (py-spy, docs/scale.md)."""

    async def one_group(group: str, payloads: list[dict]) -> None:
        for payload in payloads:
            if time.monotonic() < _quiet_until:
                return  # one failed: the rest are skipped, as send skips them
            await _send_logged(layer, group, payload)

    groups = list(_by_group(pushes).items())
    for start in range(0, len(groups), GROUPS_AT_ONCE):
        await asyncio.gather(
            *(one_group(group, payloads) for group, payloads in groups[start : start + GROUPS_AT_ONCE])
        )


def _lost(group: str, exc: Exception) -> None:
    global _quiet_until
    _quiet_until = time.monotonic() + QUIET_S
    log.warning("push to %s lost (Redis: %r); pushes paused %g s", group, exc, QUIET_S)


async def _send_bounded(layer, group: str, payload: dict) -> None:
    await asyncio.wait_for(layer.group_send(group, payload), SEND_TIMEOUT_S)


async def _send_logged(layer, group: str, payload: dict) -> None:
    try:
        await _send_bounded(layer, group, payload)
    except Exception as exc:
        _lost(group, exc)


def send_on_commit(group: str, payload: dict) -> None:
    """Send once the current transaction commits, so browsers never see state the database lacks."""
    transaction.on_commit(lambda: send(group, payload))


def robot_status(robot) -> None:
    """A robot's link status or state changed."""
    payload = RobotStatus(
        type="robot.status",
        robot=robot.name,
        id=robot.pk,
        link_status=robot.link_status,
        state=robot.state,
        last_seen=robot.last_seen.isoformat() if robot.last_seen else None,
        stop_hold=getattr(robot, "hold_words", None),
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def transition(robot, record) -> None:
    """A stored StateTransition, pushed to the fleet and the robot's page."""
    payload = StateChange(
        type="robot.transition",
        robot=robot.name,
        id=robot.pk,
        from_state=record.from_state,
        to_state=record.to_state,
        at=record.at.isoformat(),
        reason=record.reason,
        instruction=record.instruction_id,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def instruction(instruction) -> None:
    """An instruction's status or outcome changed."""
    send_on_commit(
        FLEET_GROUP,
        InstructionUpdate(
            type="instruction.update",
            id=instruction.pk,
            text=instruction.text,
            status=instruction.status,
            outcome=instruction.outcome,
            expired=bool(getattr(instruction, "expired", False)),
            photos=instruction.photo_urls() if instruction.is_final else [],
        ),
    )


def queue(payload: dict) -> None:
    """A robot's task list changed (execution.queues.robot_queue): what it runs and what waits behind it."""
    message = RobotQueue(type="robot.queue", **payload)
    send_on_commit(FLEET_GROUP, message)
    send_on_commit(robot_group(payload["id"]), message)


def alert(alert: dict, open_count: int) -> None:
    """An alert was raised, repeated, acknowledged or resolved (every page shows a badge and a toast)."""
    send_on_commit(ALERTS_GROUP, AlertUpdate(type="alert.update", alert=alert, open_count=open_count))


# Poses travel on their own group: high-rate telemetry, one batched message per tick for the whole fleet.
POSES_GROUP = "fleet.poses"


class RobotPose(TypedDict):
    id: int
    x: float
    y: float
    yaw: float
    v: float  # linear speed, m/s
    w: float  # angular speed, rad/s
    t: float  # unix time the pose was taken (its age says how stale it is)
    battery: NotRequired[float]  # percent, from the robot's bound sensor_msgs/BatteryState, when it has one
    rtt: NotRequired[float]  # ms, the round trip of a ping on the link to the robot's endpoint
    fault: NotRequired[str]  # why its odometry is refused now ("x is NaN"): x, y, yaw are the last good ones
    fault_since: NotRequired[float]  # unix time the odometry began to be refused


class PoseBatch(TypedDict):
    type: str  # "fleet.poses"
    poses: list[RobotPose]


class LeaseUpdate(TypedDict):
    type: str  # "lease.update"
    id: int
    robot: str
    holder: str | None
    expires_at: str | None


class GoalUpdate(TypedDict):
    type: str  # "robot.goal"
    id: int
    robot: str
    name: str | None
    x: float | None
    y: float | None


class RobotPath(TypedDict):
    type: str  # "robot.path"
    id: int
    robot: str
    path: list[list[float]] | None  # the route it has reserved, [[x, y], ...]; None: unchanged; []: none
    waiting_for: str | None  # the robot it waits for to make way, if any


class RobotScan(TypedDict):
    type: str  # "robot.scan"
    id: int
    topic: str
    scan: dict  # angle_min, angle_increment, range_min, range_max, ranges (m, rounded; null: no return)


class RobotCamera(TypedDict):
    type: str  # "robot.camera"
    id: int
    topic: str
    format: str  # sensor_msgs/CompressedImage's format: "jpeg", "png" (maybe with the encoding before it)
    data: str  # the image, base64 (as rosbridge sends uint8[])


def scan(robot_id: int, topic: str, message: dict) -> RobotScan:
    """One laser scan for a robot's page or a map's selected robot (sent by portal.feeds, on its socket)."""
    ranges = [round(r, 3) if isinstance(r, int | float) else None for r in message.get("ranges") or []]
    fields = ("angle_min", "angle_increment", "range_min", "range_max")
    return RobotScan(
        type="robot.scan",
        id=robot_id,
        topic=topic,
        scan={**{k: message.get(k) for k in fields}, "ranges": ranges},
    )


def camera(robot_id: int, topic: str, message: dict) -> RobotCamera:
    """One camera frame for a robot's page (sent by portal.feeds, on its socket)."""
    return RobotCamera(
        type="robot.camera",
        id=robot_id,
        topic=topic,
        format=str(message.get("format", "")),
        data=message.get("data", ""),
    )


class RobotDiagnostics(TypedDict):
    type: str  # "robot.diagnostics"
    id: int
    topic: str
    statuses: list[
        dict
    ]  # name, level (0 OK, 1 WARN, 2 ERROR, 3 STALE), level_name, message, hardware_id, values


DIAGNOSTIC_LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
TEXT_MAX = 200  # a robot's words (a status's name, message, a value) are cut to this many characters


def _text(value) -> str:
    return str(value if value is not None else "")[:TEXT_MAX]


def _level(value) -> int:
    """A DiagnosticStatus level as a number (rosbridge sends a ROS 2 byte as a one-character string or bytes)."""
    if isinstance(value, str) and len(value) == 1:
        value = ord(value)
    return value if isinstance(value, int) and value in DIAGNOSTIC_LEVELS else 3


def diagnostics(robot_id: int, topic: str, statuses: list) -> RobotDiagnostics:
    """A robot's statuses from one diagnostic_msgs/DiagnosticArray (portal.feeds keeps the robot's own); a level
    outside OK/WARN/ERROR/STALE is said STALE; text cut to TEXT_MAX (the page shows it as text, never markup)."""
    out = []
    for status in statuses[:100]:
        if not isinstance(status, dict):
            continue
        level = _level(status.get("level"))
        values = status.get("values") if isinstance(status.get("values"), list) else []
        out.append({
            "name": _text(status.get("name")), "level": level, "level_name": DIAGNOSTIC_LEVELS[level],
            "message": _text(status.get("message")), "hardware_id": _text(status.get("hardware_id")),
            "values": [[_text(v.get("key")), _text(v.get("value"))] for v in values[:20] if isinstance(v, dict)],
        })  # fmt: skip
    return RobotDiagnostics(type="robot.diagnostics", id=robot_id, topic=topic, statuses=out)


class RobotTopic(TypedDict):
    type: str  # "robot.topic"
    id: int
    topic: str
    msg_type: str
    rate_hz: float | None  # messages a second seen over the last few seconds (None: fewer than two yet)
    capped: bool  # the rate is at the inspector's cap: the topic may publish faster
    count: int  # messages seen since the inspector started
    text: str  # the latest message as indented JSON, long arrays and strings shortened


def topic_message(robot_id: int, topic: str, msg_type: str, rate: dict, text: str) -> RobotTopic:
    """The topic inspector's latest message of a robot's topic (portal.inspector)."""
    return RobotTopic(type="robot.topic", id=robot_id, topic=topic, msg_type=msg_type, text=text, **rate)


class RegistrationProgress(TypedDict, total=False):
    type: str  # "registration.progress"
    endpoint: str
    stage: str  # e.g. connecting, discovering, identifying, done, failed
    message: str
    robots: list[str]
    ok: bool | None


def lease(robot, current=None) -> None:
    """A robot's control lease was taken, renewed, released or taken over (current: the lease now, or None)."""
    active = current is not None and current.active
    payload = LeaseUpdate(
        type="lease.update",
        id=robot.pk,
        robot=robot.name,
        holder=current.user.username if active else None,
        expires_at=current.expires_at.isoformat() if active else None,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def goal(robot, name: str | None, x: float | None, y: float | None) -> None:
    """A robot's current goal changed (None clears it); the map draws it."""
    payload = GoalUpdate(type="robot.goal", id=robot.pk, robot=robot.name, name=name, x=x, y=y)
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def path(robot, points, waiting_for: str | None) -> None:
    """A robot's reserved route changed (points; None leaves it as drawn), or whom it waits for; the map
    draws both. Sent at once: the executor pushes it from its loop, outside any transaction."""
    payload = RobotPath(
        type="robot.path",
        id=robot.pk,
        robot=robot.name,
        path=None if points is None else [[float(x), float(y)] for x, y in points],
        waiting_for=waiting_for,
    )
    send_on_commit(FLEET_GROUP, payload)
    send_on_commit(robot_group(robot.pk), payload)


def registration(endpoint: str, stage: str, message: str = "", robots=(), ok: bool | None = None) -> None:
    """Progress of one endpoint's registration, for the registration page."""
    send_on_commit(
        FLEET_GROUP,
        RegistrationProgress(
            type="registration.progress",
            endpoint=endpoint,
            stage=stage,
            message=message,
            robots=list(robots),
            ok=ok,
        ),
    )


def poses(batch: list[RobotPose]) -> PoseBatch:
    """The message for one tick of poses (sent by robots.poses, which owns the rate)."""
    return PoseBatch(type="fleet.poses", poses=batch)
