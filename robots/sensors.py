"""Which topics show a robot's sensors on its page: its battery, its laser scan and its camera.

The battery and the scan are the robot's bindings (fleetcore.bindings roles); a camera is any topic of its
graph that carries sensor_msgs/CompressedImage (what a browser can show as it comes: a JPEG or PNG).
"""

from __future__ import annotations

from dataclasses import dataclass

CAMERA_TYPES = ("sensor_msgs/CompressedImage", "sensor_msgs/msg/CompressedImage")
SCAN_TYPES = ("sensor_msgs/LaserScan", "sensor_msgs/msg/LaserScan")


@dataclass(frozen=True)
class Feed:
    topic: str
    type: str


def feeds(robot) -> dict[str, Feed]:
    """{"battery" | "scan" | "camera": Feed} for the feeds this robot has (bindings first, then its topics)."""
    bound = {b.action: b for b in robot.bindings.all() if b.target}
    out = {
        role: Feed(bound[role].target, bound[role].message_type)
        for role in ("battery", "scan")
        if role in bound
    }
    topics = list(robot.topics.filter(type__in=CAMERA_TYPES + SCAN_TYPES).order_by("name"))
    camera = next((t for t in topics if t.type in CAMERA_TYPES), None)
    if camera is not None:
        out["camera"] = Feed(camera.name, camera.type)
    scan = next((t for t in topics if t.type in SCAN_TYPES), None)
    if "scan" not in out and scan is not None:
        out["scan"] = Feed(scan.name, scan.type)
    return out
