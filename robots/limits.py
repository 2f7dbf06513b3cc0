"""Caps on what one robot endpoint may send us: robots are untrusted input (no Django here).

A rosbridge endpoint is whatever answers at an address an admin typed; it may be buggy, misconfigured or
hostile. Every size it controls is bounded here, each by one setting (fleet/settings.py, the block "Robots
are untrusted input"), and each refusal names the setting to raise:

- frame_bytes: one WebSocket frame, and one reassembled rosbridge `fragment` message (the client closes the
  link on a bigger frame: websockets reads the length first, so the frame is never held in memory);
- topics: the topics one endpoint lists (its robots' graphs are stored and shown, row by row);
- urdf_bytes: one robot_description (parsed as XML into memory);
- frames_per_s: inbound frames per endpoint link and second beyond what the link's throttled subscriptions ask
  for (robots.rosbridge.inflow: a token bucket holding one second's worth; what exceeds it is dropped unread and
  counted, so one flooding endpoint cannot starve the others' links).

The process-wide values are set once from Django settings (robots.apps.RobotsConfig.ready) and again when a
test overrides a setting; every RosbridgeClient and every registration reads them through current().
"""

from __future__ import annotations

from dataclasses import dataclass

MB = 1024 * 1024

FRAME_SETTING = "FLEET_ROBOT_MAX_FRAME_MB"
TOPICS_SETTING = "FLEET_ROBOT_MAX_TOPICS"
URDF_SETTING = "FLEET_ROBOT_MAX_URDF_MB"
RATE_SETTING = "FLEET_ROBOT_MAX_FRAMES_PER_S"


@dataclass(frozen=True)
class Limits:
    """The caps in bytes and counts; defaults are the settings' defaults."""

    frame_bytes: int = 16 * MB
    topics: int = 100_000
    urdf_bytes: int = 4 * MB
    frames_per_s: int = 2000  # a warehouse endpoint's 14 robots at 20 Hz odometry send 280


_current = Limits()


def current() -> Limits:
    """The caps in force in this process."""
    return _current


def configure(limits: Limits) -> None:
    """Replace the caps in force (at start-up, from settings)."""
    global _current
    _current = limits


def megabytes(size: int) -> str:
    """A byte count as people read it in a refusal: 16 MB, 0.5 MB."""
    return f"{size / MB:.3g} MB"
