"""The gate a robot's odometry passes before it becomes a pose, in every process that reads poses.

A message is refused when a number in it is NaN or infinite, when it moves the robot faster than the robot can
move (its top speed times SPEED_MARGIN over the time between the two messages, plus JUMP_SLACK_M), or when its
stamp runs ahead of the robot's own clock (further than a simulator's fastest time scale allows since the last
message, or more than AHEAD_S ahead of ours at the first). A refused message leaves the robot flagged with the
reason until its odometry is good again: back in line with the last good pose (a spike), or in line with itself
for SETTLE_S (the odometry was reset: its new frame is taken).

    gate = PoseGate(max_linear=1.0)
    reading = gate.admit(message, time.time())   # InvalidOdometry("x is NaN") when refused; gate.fault says it
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NoReturn

from fleetcore.geometry import NonFinite, Pose2D, pose_of, twist_of
from fleetcore.motion import RATE_BOUNDS, stamp_of

SPEED_MARGIN = 2.0  # odometry may move at up to twice the robot's top speed (noise, a coarse simulator step)
JUMP_SLACK_M = 0.5  # and this far beyond it, whatever the time between two messages
MIN_SPEED = 0.5  # m/s: the top speed assumed for a robot registered with none
FUTURE_SLACK_S = 1.0  # s a stamp may run ahead of what the robot's clock can have reached
AHEAD_S = 24 * 3600.0  # s ahead of our clock a first stamp may be (a simulator run long at a fast time scale)
SETTLE_S = 2.0  # s of odometry in line with itself after a jump: the new frame is taken (an odometry reset)


class InvalidOdometry(ValueError):
    """The message was refused at the gate; the message says why ("x is NaN")."""


@dataclass(frozen=True)
class Reading:
    """One admitted odometry message: the pose in the odometry frame, the twist, the stamp (None if missing)."""

    pose: Pose2D
    v: float
    w: float
    stamp: float | None


def read(message: dict) -> Reading:
    """The reading of one nav_msgs/Odometry; NonFinite naming a NaN or infinite field."""
    stamp = stamp_of(message)
    if stamp is not None and not math.isfinite(stamp):
        raise NonFinite("stamp is not finite")
    v, w = twist_of(message)
    return Reading(pose_of(message), v, w, stamp)


@dataclass
class _Seen:
    reading: Reading
    wall: float
    since: float = 0.0  # wall time a chain of refused readings in line with each other began


class PoseGate:
    """One robot's odometry gate: admit() each message; fault and since say why and since when it refuses."""

    def __init__(self, max_linear: float) -> None:
        self.max_linear = max_linear if max_linear and max_linear > 0 else MIN_SPEED
        self.fault: str | None = None
        self.since: float | None = None  # wall time the fault began
        self._good: _Seen | None = None  # the last reading admitted
        self._chain: _Seen | None = None  # the last reading refused for a jump or a stamp

    def admit(self, message: dict, wall: float) -> Reading:
        """The message's reading when it passes; InvalidOdometry with the reason (the robot flagged) if not."""
        try:
            reading = read(message)
        except NonFinite as exc:
            self._chain = None
            self._refuse(str(exc), wall)
        reason = self._judge(reading, wall)
        if reason is not None:
            self._follow_chain(reading, wall)
            self._refuse(reason, wall)
        self._good, self._chain = _Seen(reading, wall), None
        self.fault = self.since = None
        return reading

    def _refuse(self, reason: str, wall: float) -> NoReturn:
        if self.fault is None:
            self.since = wall
        self.fault = reason
        raise InvalidOdometry(reason)

    def _judge(self, reading: Reading, wall: float) -> str | None:
        if self._good is None:
            ahead = (reading.stamp or 0.0) - wall
            reason = f"stamp from the future ({ahead:.0f} s ahead of our clock)" if ahead > AHEAD_S else None
        else:
            reason = self._against(self._good, reading, wall)
        chain = self._chain
        settled = chain is not None and wall - chain.since >= SETTLE_S
        if reason is not None and settled and self._against(chain, reading, wall) is None:
            return None  # in line with itself for SETTLE_S: the odometry was reset, its new frame is taken
        return reason

    def _follow_chain(self, reading: Reading, wall: float) -> None:
        """Remember a refused reading; one in line with the previous refused one continues its chain."""
        chain = self._chain
        in_line = chain is not None and self._against(chain, reading, wall) is None
        self._chain = _Seen(reading, wall, chain.since if in_line else wall)

    def _against(self, before: _Seen, reading: Reading, wall: float) -> str | None:
        """Why reading cannot follow before (a stamp from the future, a jump), or None."""
        elapsed = max(wall - before.wall, 0.0)
        if reading.stamp is not None and before.reading.stamp is not None:
            lead = reading.stamp - before.reading.stamp - elapsed * RATE_BOUNDS[1]
            if lead > FUTURE_SLACK_S:
                return f"stamp from the future ({lead:.0f} s ahead of its clock)"
            back = before.reading.stamp - reading.stamp
            if back > FUTURE_SLACK_S:  # a default-filled message (stamp 0) or a replay: no pose of now
                return f"stamp went back {back:.1f} s"
        stamped = reading.stamp is not None and before.reading.stamp is not None
        dt = reading.stamp - before.reading.stamp if stamped else -1.0
        if (
            dt <= 0
        ):  # no stamps, stamps that stand still or go back: the fastest a simulator runs, in wall time
            dt = elapsed * RATE_BOUNDS[1]
        jump = math.dist(before.reading.pose[:2], reading.pose[:2])
        if jump > self.max_linear * SPEED_MARGIN * dt + JUMP_SLACK_M:
            return f"jumped {jump:.1f} m in {dt:.2f} s, faster than its {self.max_linear:g} m/s"
        return None
