"""Which topics show a robot's sensors on its page: its battery, its laser scan, its camera and its diagnostics.

The battery, the scan and the camera are the robot's bindings (fleetcore.bindings roles) where it has them. The
page's camera shows sensor_msgs/CompressedImage only (what a browser can show as it comes: a JPEG or PNG): a
camera bound to raw frames, or none bound, shows the first compressed topic of the robot's graph instead.
"""

from __future__ import annotations

from dataclasses import dataclass

CAMERA_TYPES = ("sensor_msgs/CompressedImage", "sensor_msgs/msg/CompressedImage")
SCAN_TYPES = ("sensor_msgs/LaserScan", "sensor_msgs/msg/LaserScan")
DIAGNOSTICS_STALE_S = (
    5.0  # a component not heard from in this long is STALE (diagnostic_updater sends each 1 s)
)
DIAGNOSTICS_TYPES = ("diagnostic_msgs/DiagnosticArray", "diagnostic_msgs/msg/DiagnosticArray")


@dataclass(frozen=True)
class Feed:
    topic: str
    type: str


def feeds(robot) -> dict[str, Feed]:
    """{"battery" | "scan" | "camera": Feed} for the feeds this robot has (bindings first, then its topics)."""
    bound = {b.action: b for b in robot.bindings.all() if b.target}
    out = {
        role: Feed(bound[role].target, bound[role].message_type)
        for role in ("battery", "scan", "camera")
        if role in bound
    }
    if out.get("camera") and out["camera"].type not in CAMERA_TYPES:
        del out["camera"]  # raw frames: a photo can be taken from them, a browser cannot show them
    topics = list(
        robot.topics.filter(type__in=CAMERA_TYPES + SCAN_TYPES + DIAGNOSTICS_TYPES).order_by("name")
    )
    camera = next((t for t in topics if t.type in CAMERA_TYPES), None)
    if "camera" not in out and camera is not None:
        out["camera"] = Feed(camera.name, camera.type)
    scan = next((t for t in topics if t.type in SCAN_TYPES), None)
    if "scan" not in out and scan is not None:
        out["scan"] = Feed(scan.name, scan.type)
    diagnostics = next((t for t in topics if t.type in DIAGNOSTICS_TYPES), None)
    if diagnostics is not None:
        out["diagnostics"] = Feed(diagnostics.name, diagnostics.type)
    return out


@dataclass(frozen=True)
class DiagnosticsOwner:
    """Which statuses of a /diagnostics array are this robot's. A robot alone on its endpoint owns them all; robots
    sharing one (namespaced) own those whose name or hardware_id says their namespace or name (diagnostic_updater
    names a status after its node, so "robot1/battery" or "/robot1/turtlebot3_diagnostics: Battery")."""

    name: str
    namespace: str
    shared: bool

    @classmethod
    def of(cls, robot) -> DiagnosticsOwner:
        shared = type(robot).objects.filter(endpoint=robot.endpoint).exclude(pk=robot.pk).exists()
        return cls(robot.name, robot.namespace.strip("/"), shared)

    def owns(self, status: dict) -> bool:
        if not self.shared:
            return True
        said = f"{status.get('name', '')} {status.get('hardware_id', '')}"
        words = said.replace("/", " ").replace(":", " ").split()
        return self.name in words or bool(self.namespace and self.namespace in words)
