"""How fast a step goes, for every kind of robot: the one function from a speed word to the limits driven.

A speed word ("slowly" is read "slow"; none is "normal") asks each robot for a share of its own limits. The
share is used the same way everywhere, through `pace(word, limits)`: the portal's controller drives at that share
of the robot's linear and angular limits (`Pace.limits`), a navigation stack is held at that share of its own top
speed (`Pace.stack_share`: nav2's speed limit, move_base's max_vel_x), traffic times the robot's plans by it
(`Pace.planned`), its stretches and motions are given time by it (`Pace.stack_limits`, `Pace.limits`), and the
queue's ETA reads it. Nothing else multiplies a limit by a speed word's share.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetcore import traffic_tuning as tune

# A speed word -> the share of each robot's own velocity limits it asks for. None means "normal".
SPEEDS: dict[str, float] = {"very slow": 0.2, "slow": 0.35, "normal": 0.6, "fast": 0.85, "very fast": 1.0}
DEFAULT_SPEED = "normal"


class UnknownSpeed(ValueError):
    """A speed word nobody defined; the message names the words there are."""


@dataclass(frozen=True)
class Limits:
    """A robot's velocity limits (m/s, rad/s)."""

    linear: float
    angular: float

    def __post_init__(self):
        if not (self.linear > 0 and self.angular > 0):
            raise ValueError(f"limits must be positive, got linear={self.linear}, angular={self.angular}")

    def scaled(self, share: float) -> Limits:
        return Limits(self.linear * share, self.angular * share)


@dataclass(frozen=True)
class Pace:
    """What one speed word asks of one robot (its own limits `top`)."""

    word: str
    top: Limits
    share: float  # of the robot's own limits (SPEEDS)

    @property
    def limits(self) -> Limits:
        """The limits the portal's controller drives at, and gives a motion time by."""
        return self.top.scaled(self.share)

    @property
    def stack_share(self) -> float | None:
        """The share of a navigation stack's own top speed to hold it at (a robot's limits, for a stack, are its
        planner's: nav2's controller, move_base's local planner); None: its own top speed, no limit."""
        return None if self.share >= 1.0 else self.share

    @property
    def stack_limits(self) -> Limits:
        """The pace a nav stack's stretches are given time at: a stack drives slower than the robot can (its own
        planner's top speed, at most NAV_TOP_MPS, and its ramps and turns: NAV_PACE_GUESS), at the word's share."""
        guess = min(self.top.linear, tune.NAV_TOP_MPS) * tune.NAV_PACE_GUESS * self.share
        return self.top.scaled(guess / self.top.linear)

    def planned(self, nav: bool, learned: float | None = None) -> float:
        """The speed (m/s of the robot's clock) traffic plans this robot at: the controller's speed, slowed by
        turns and ramps (PLANNED_SPEED); a nav stack at the pace it was seen to drive (learned) and, until it is
        seen, at the robot's own top speed. A plan faster than the robot only makes it late against its
        reservations, where the claims hold it; after its first stretch it replans at the pace seen. (A guess
        slower than the stack, 0.11 m/s for a TIAGo driving 0.5, made plans longer than the search's horizon,
        and robots early against all of them.)"""
        speed = (learned or self.top.linear) if nav else self.limits.linear
        return speed * tune.PLANNED_SPEED


def word(said: str | None) -> str:
    """The speed word a step's speed stands for ("normal" for none); UnknownSpeed for a word nobody defined."""
    key = DEFAULT_SPEED if said is None or said == "" else str(said).strip().lower()
    if key not in SPEEDS:
        raise UnknownSpeed(f"unknown speed {said!r}; say one of: {', '.join(SPEEDS)}")
    return key


def pace(said: str | None, limits: Limits) -> Pace:
    """What the speed word `said` asks of a robot with these limits: the one place a word becomes a speed."""
    key = word(said)
    return Pace(key, limits, SPEEDS[key])
