"""Record the fleet for N seconds: what the portal pushes to browsers (poses, state changes, instructions, goals,
alerts) and, if asked, raw command topics from the robots' endpoints, into one MCAP file (recordings.mcapfile).

The recorder listens where every browser listens: it joins the live groups on the channel layer (`live`), so a
recording holds exactly what an operator saw, from any process that reaches Redis.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from pathlib import Path

from asgiref.sync import sync_to_async
from channels.layers import get_channel_layer
from django.conf import settings
from django.utils import timezone

import live
from recordings.mcapfile import RecordingWriter
from recordings.models import Recording
from robots.models import Robot
from robots.poses import last_poses
from robots.rosbridge import RosbridgeClient

log = logging.getLogger(__name__)
MAX_SECONDS = 3600
RAW_TYPES = ("geometry_msgs/Twist", "geometry_msgs/msg/Twist")


class RecordingError(ValueError):
    """A recording that cannot start; the message says why."""


def recordings_dir() -> Path:
    path = Path(settings.VAR_DIR) / "recordings"
    path.mkdir(parents=True, exist_ok=True)
    return path


def parse_raw_topics(values) -> list[tuple[str, str, str]]:
    """ "robot:/topic" strings as (robot, topic, type); the robot must have that topic, and it must be a Twist."""
    chosen = []
    for value in values:
        robot_name, _, topic = str(value).partition(":")
        if not topic.startswith("/"):
            raise RecordingError(f"raw topic {value!r}: expected robot:/topic, e.g. husky:/cmd_vel")
        robot = Robot.objects.filter(name=robot_name).first()
        if robot is None:
            raise RecordingError(f"raw topic {value!r}: no robot named {robot_name!r}")
        known = robot.topics.filter(name=topic).first()
        if known is None or known.type not in RAW_TYPES:
            raise RecordingError(
                f"raw topic {value!r}: {robot_name} has no Twist topic {topic} (only Twist is recorded raw)"
            )
        chosen.append((robot_name, topic, known.type))
    return chosen


def create(user, seconds: float, raw_topics=(), path: Path | None = None) -> Recording:
    """Validate and store a recording to make (its file under var/recordings/ unless a path is given)."""
    if not 0 < seconds <= MAX_SECONDS:
        raise RecordingError(f"seconds: from 0 to {MAX_SECONDS}, got {seconds:g}")
    parse_raw_topics(raw_topics)
    recording = Recording.objects.create(user=user, seconds=seconds, raw_topics=list(raw_topics), path="")
    recording.path = str(path or recordings_dir() / f"recording-{recording.pk}.mcap")
    recording.save(update_fields=["path"])
    return recording


def run(recording_pk: int) -> Recording:
    """Make one stored recording now (blocking for its seconds); a recording already taken is left alone."""
    claimed = Recording.objects.filter(pk=recording_pk, status=Recording.Status.QUEUED).update(
        status=Recording.Status.RECORDING, started_at=timezone.now()
    )
    recording = Recording.objects.get(pk=recording_pk)
    if not claimed:
        return recording
    try:
        counts = asyncio.run(
            record(Path(recording.path), recording.seconds, parse_raw_topics(recording.raw_topics))
        )
    except Exception as exc:  # stored for the page to show
        log.exception("recording %s failed", recording.pk)
        recording.status, recording.error = Recording.Status.FAILED, f"{type(exc).__name__}: {exc}"
    else:
        recording.status, recording.counts = Recording.Status.FINISHED, counts
    recording.finished_at = timezone.now()
    recording.save(update_fields=["status", "error", "counts", "finished_at"])
    return recording


async def record(
    path: Path, seconds: float, raw_topics=(), ready: asyncio.Event | None = None
) -> dict[str, int]:
    """Listen to the live groups (and the raw topics) for `seconds`, writing each message; the counts written."""
    layer = get_channel_layer()
    if layer is None:
        raise RecordingError("no channel layer configured: nothing to listen to")
    names = await sync_to_async(_robot_names)()
    writer = RecordingWriter(path)
    channel = await layer.new_channel("recorder.")
    groups = (live.FLEET_GROUP, live.POSES_GROUP, live.ALERTS_GROUP)
    for group in groups:
        await layer.group_add(group, channel)
    raw = await _subscribe_raw(writer, raw_topics)
    await _write_last_poses(writer, names, time.time())
    if ready is not None:
        ready.set()
    try:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            try:
                message = await asyncio.wait_for(layer.receive(channel), timeout=min(left, 1.0))
            except TimeoutError:
                continue
            for one in live.unbatched(message):  # a together() block's pushes come in one message
                await _write(writer, one, names)
    finally:
        for group in groups:
            await layer.group_discard(group, channel)
        for client in raw:
            with contextlib.suppress(Exception):
                await client.close()
        counts = writer.close()
    return counts


def _robot_names() -> dict[int, str]:
    return dict(Robot.objects.values_list("pk", "name"))


async def _write_last_poses(writer: RecordingWriter, names: dict[int, str], start: float) -> None:
    """Every robot's last pose, at the recording's start: a replay at t = 0 shows the whole fleet, not only the
    robots whose poses happened to come first."""
    poses = await sync_to_async(last_poses)(list(names))
    for robot_id, pose in sorted(poses.items()):
        writer.pose(names[robot_id], pose["x"], pose["y"], pose["yaw"], start)


GAP = "recording_gap"
GAP_WORDS = (
    "the live pushes' connection to Redis was cut and taken again: what was pushed in between is missing"
)


async def _write(writer: RecordingWriter, message: dict, names: dict[int, str]) -> None:
    kind, now = message.get("type"), time.time()
    if kind == "fleet.poses":
        for pose in message.get("poses", []):
            if "x" not in pose:  # refused at the gate from its first message: no place to record
                continue
            if pose["id"] not in names:
                names.update(await sync_to_async(_robot_names)())
            name = names.get(pose["id"], f"robot{pose['id']}")
            writer.pose(name, pose["x"], pose["y"], pose["yaw"], pose.get("t") or now)
    elif kind == "robot.transition":
        m = message
        writer.transition(
            m["robot"], m["from_state"], m["to_state"], m.get("reason", ""), m.get("instruction"), now
        )
    elif kind == "instruction.update":
        writer.instruction(
            message["id"], message.get("text", ""), message.get("status", ""), message.get("outcome", ""), now
        )
    elif kind == "robot.goal":
        writer.goal(message["robot"], message.get("name"), message.get("x"), message.get("y"), now)
    elif kind == "alert.update":
        writer.alert(message.get("alert") or {}, now)
    elif kind == live.RESUBSCRIBED:  # the layer's subscription was cut: what was pushed meanwhile is not here
        writer.alert({"kind": GAP, "severity": "warning", "message": GAP_WORDS, "status": "open"}, now)


async def _subscribe_raw(writer: RecordingWriter, raw_topics) -> list:
    """One rosbridge connection per endpoint of the chosen raw topics, each topic subscribed into the file."""
    clients, by_url = [], {}
    for robot_name, topic, type_ in raw_topics:
        robot = await Robot.objects.aget(name=robot_name)
        url = robot.endpoint
        if url not in by_url:
            by_url[url] = RosbridgeClient(url, ping_interval=None)
            await by_url[url].connect()
            clients.append(by_url[url])

        def on_message(msg, robot_name=robot_name, topic=topic):
            writer.twist(robot_name, topic, msg, time.time())

        await by_url[url].subscribe(topic, type_, on_message)
    return clients
