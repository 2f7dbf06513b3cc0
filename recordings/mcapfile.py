"""The recording's file format: MCAP with ROS 2 message encodings (CDR), as Foxglove and `ros2 bag` read it.

Why ROS 2 (`mcap-ros2-support`) rather than ROS 1: its writer encodes plain dicts against a message definition
given as text, so no generated message classes are needed; the definitions travel inside the file, so the fleet's
own types (state transitions, instructions, alerts) open in Foxglove like the standard ones.

Topics:
    /fleet/<robot>/pose       geometry_msgs/msg/PoseStamped   every pose the portal pushed (frame "map")
    /fleet/state              fleet_msgs/msg/StateTransition  each robot state change, with its reason
    /fleet/instructions       fleet_msgs/msg/Instruction      each instruction's text and status as it changed
    /fleet/goals              fleet_msgs/msg/Goal             a robot's goal set or cleared
    /fleet/alerts             fleet_msgs/msg/Alert            alerts raised, acknowledged, resolved
    /raw/<robot><topic>       geometry_msgs/msg/Twist         a chosen raw command topic, as the robot received it
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer

SEPARATOR = "=" * 80
TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id"
POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z"
QUATERNION = "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w"
POSE = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation"
VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z"


def _definition(main: str, *dependencies: str) -> str:
    return "\n".join([main, *(f"{SEPARATOR}\n{d}" for d in dependencies)])


SCHEMAS = {
    "geometry_msgs/msg/PoseStamped": _definition(
        "std_msgs/Header header\ngeometry_msgs/Pose pose", HEADER, TIME, POSE, POINT, QUATERNION
    ),
    "geometry_msgs/msg/Twist": _definition("Vector3 linear\nVector3 angular", VECTOR3),
    "fleet_msgs/msg/StateTransition": (
        "string robot\nstring from_state\nstring to_state\nstring reason\nint64 instruction"
    ),
    "fleet_msgs/msg/Instruction": "int64 id\nstring text\nstring status\nstring outcome",
    "fleet_msgs/msg/Goal": "string robot\nstring name\nbool cleared\nfloat64 x\nfloat64 y",
    "fleet_msgs/msg/Alert": (
        "int64 id\nstring kind\nstring severity\nstring robot\nstring message\nstring status\nuint32 count"
    ),
}
TOPIC_SCHEMAS = {  # fixed topics; poses and raw topics are per robot
    "/fleet/state": "fleet_msgs/msg/StateTransition",
    "/fleet/instructions": "fleet_msgs/msg/Instruction",
    "/fleet/goals": "fleet_msgs/msg/Goal",
    "/fleet/alerts": "fleet_msgs/msg/Alert",
}


def pose_topic(robot: str) -> str:
    return f"/fleet/{robot}/pose"


def raw_topic(robot: str, topic: str) -> str:
    return f"/raw/{robot}/{topic.lstrip('/')}"


def _stamp(t: float) -> dict:
    sec = math.floor(t)
    return {"sec": sec, "nanosec": int((t - sec) * 1e9)}


class RecordingWriter:
    """Writes the fleet's messages into one MCAP file; counts what it wrote per topic."""

    def __init__(self, path: Path):
        self.path = path
        self._file = open(path, "wb")  # noqa: SIM115 (closed in close())
        self._writer = Writer(self._file)
        self._schemas = {name: self._writer.register_msgdef(name, text) for name, text in SCHEMAS.items()}
        self.counts: Counter[str] = Counter()

    def _write(self, topic: str, schema: str, message: dict, t: float) -> None:
        ns = int(t * 1e9)
        self._writer.write_message(topic, self._schemas[schema], message, log_time=ns, publish_time=ns)
        self.counts[topic] += 1

    def pose(self, robot: str, x: float, y: float, yaw: float, t: float) -> None:
        orientation = {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}
        message = {
            "header": {"stamp": _stamp(t), "frame_id": "map"},
            "pose": {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": orientation},
        }
        self._write(pose_topic(robot), "geometry_msgs/msg/PoseStamped", message, t)

    def transition(
        self, robot: str, from_state: str, to_state: str, reason: str, instruction, t: float
    ) -> None:
        message = {
            "robot": robot,
            "from_state": from_state,
            "to_state": to_state,
            "reason": reason or "",
            "instruction": int(instruction or 0),
        }
        self._write("/fleet/state", "fleet_msgs/msg/StateTransition", message, t)

    def instruction(self, id_: int, text: str, status: str, outcome: str, t: float) -> None:
        message = {"id": int(id_), "text": text or "", "status": status or "", "outcome": outcome or ""}
        self._write("/fleet/instructions", "fleet_msgs/msg/Instruction", message, t)

    def goal(self, robot: str, name, x, y, t: float) -> None:
        cleared = x is None or y is None
        message = {
            "robot": robot,
            "name": name or "",
            "cleared": cleared,
            "x": float(x or 0),
            "y": float(y or 0),
        }
        self._write("/fleet/goals", "fleet_msgs/msg/Goal", message, t)

    def alert(self, alert: dict, t: float) -> None:
        message = {
            "id": int(alert.get("id") or 0),
            "kind": str(alert.get("kind", "")),
            "severity": str(alert.get("severity", "")),
            "robot": str(alert.get("robot") or ""),
            "message": str(alert.get("message", "")),
            "status": str(alert.get("status", "")),
            "count": int(alert.get("count") or 1),
        }
        self._write("/fleet/alerts", "fleet_msgs/msg/Alert", message, t)

    def twist(self, robot: str, topic: str, msg: dict, t: float) -> None:
        """A raw geometry_msgs Twist as rosbridge gave it (ROS 1 and 2 have the same fields)."""
        vector = lambda v: {k: float((v or {}).get(k, 0.0)) for k in "xyz"}  # noqa: E731
        message = {"linear": vector(msg.get("linear")), "angular": vector(msg.get("angular"))}
        self._write(raw_topic(robot, topic), "geometry_msgs/msg/Twist", message, t)

    def close(self) -> dict[str, int]:
        self._writer.finish()
        self._file.close()
        return dict(self.counts)


def read_messages(path: Path):
    """Every message of a recording decoded: (topic, schema name, log time in s, message object)."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            yield channel.topic, schema.name, message.log_time / 1e9, decoded


MAX_REPLAY_POSES = (
    6000  # per robot: 10 minutes at 10 Hz; a longer recording is thinned for the page (not the file)
)


def _thinned(poses: list) -> list:
    """At most MAX_REPLAY_POSES, evenly spaced, the last one kept."""
    if len(poses) <= MAX_REPLAY_POSES:
        return poses
    step = -(-len(poses) // MAX_REPLAY_POSES)
    return poses[::step] + ([poses[-1]] if (len(poses) - 1) % step else [])


def replay_frames(path: Path) -> dict:
    """What the replay page draws: each robot's poses (thinned past MAX_REPLAY_POSES) and the events in time
    order, times from the start."""
    robots: dict[str, list] = {}
    events = []
    start = end = None
    for topic, schema, t, msg in read_messages(path):
        start = t if start is None else min(start, t)
        end = t if end is None else max(end, t)
        if schema == "geometry_msgs/msg/PoseStamped":
            q = msg.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            name = topic.split("/")[2]
            robots.setdefault(name, []).append([t, msg.pose.position.x, msg.pose.position.y, yaw])
        elif schema in _EVENT_TEXT:
            events.append({"t": t, "topic": topic, "text": _EVENT_TEXT[schema](msg)})
    start = start or 0.0
    for name, poses in robots.items():
        robots[name] = poses = _thinned(poses)
        for pose in poses:
            pose[0] = round(pose[0] - start, 3)
    for event in events:
        event["t"] = round(event["t"] - start, 3)
    return {"duration": round((end or start) - start, 3), "robots": robots, "events": events}


_EVENT_TEXT = {
    "fleet_msgs/msg/StateTransition": lambda m: (
        f"{m.robot}: {m.from_state} → {m.to_state}" + (f" ({m.reason})" if m.reason else "")
    ),
    "fleet_msgs/msg/Instruction": lambda m: (
        f"instruction #{m.id} “{m.text}”: {m.status}" + (f" ({m.outcome})" if m.outcome else "")
    ),
    "fleet_msgs/msg/Goal": lambda m: (
        f"{m.robot}: goal cleared" if m.cleared else f"{m.robot}: goal {m.name or ''} ({m.x:.2f}, {m.y:.2f})"
    ),
    "fleet_msgs/msg/Alert": lambda m: f"alert {m.kind} {m.robot or 'fleet'}: {m.message} ({m.status})",
}  # raw command topics stay out of the events list (many per second): Foxglove plots them
