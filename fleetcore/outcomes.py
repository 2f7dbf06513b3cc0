"""What became of a step, in one vocabulary: decided from where the robot stands at its end, not from what its
controller or nav stack returned, and said the same way everywhere (the console's answer, the API, the robot's
history, `manage.py instruct`, recordings: all of them show the words made here).

A robot sent to a place has
- arrived at it: it stands within TOLERANCE_M of the place ("arrived at A");
- stopped at a free spot next to it: the place was taken (by a robot standing there or another's goal) and it
  stands within TOLERANCE_M of the spot it was given instead ("at a free spot 1.1 m south-west of A; A is
  taken by husky"; "A was taken when it came" when nobody stands there now; "A has no room for it" when the
  place is too tight for the robot);
- stopped elsewhere: anywhere else ("stopped 0.8 m north of A"); the step has not done what was asked.

A robot told to turn or move by an amount is said to have done what its odometry measured once at rest: the
amount asked when it is within SAID_AS_ASKED_DEG or SAID_AS_ASKED_M of it ("turned 90° left"), else the measure
with what was asked ("turned 104° left (90° left asked)": a robot whose control ticks came late under load slowed
down past its mark).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fleetcore.traffic import compass

TOLERANCE_M = 0.25  # m from a place a robot is at it: nav stacks stop within 0.15 m, the route driver 0.1 m,
# and odometry read a moment after the stop may have it a few centimetres on
HERE_M = 0.05  # m: nearer than this, a spot is the place itself in words

ARRIVED, FREE_SPOT, STOPPED = "arrived", "free spot", "stopped"
SAID_AS_ASKED_DEG = 3.0  # a turn within this of what was asked is said as asked
SAID_AS_ASKED_M = 0.03  # a move by an amount within this of what was asked is said as asked


@dataclass(frozen=True)
class Ending:
    """Where a robot sent to a place ended: its kind (ARRIVED, FREE_SPOT, STOPPED) and the words for it."""

    kind: str
    words: str
    where: str  # "at A", "at a free spot 1.1 m south-west of A", "0.8 m north of A": for what it did there

    @property
    def reached(self) -> bool:
        """Whether the robot is where it was sent (the place, or the free spot it was given instead)."""
        return self.kind != STOPPED


def offset(place: str, center, point) -> str:
    """ "1.1 m south-west of A" (from the place's centre to the point); "at A" when nearer than HERE_M."""
    distance = math.dist(center, point)
    if distance < HERE_M:
        return f"at {place}"
    return f"{distance:.1f} m {compass(center, point)} of {place}"


def judge(
    place: str,
    center,
    spot,
    pose,
    taken_by: str | None = None,
    tolerance: float = TOLERANCE_M,
    fits: bool = False,
) -> Ending:
    """The ending of a step that sent a robot to `place` (at `center`) and gave it `spot` (the place itself, or
    a free spot next to it when the place was taken, by `taken_by`), by the robot's pose at the end. fits: the
    robot fits at the place (a spot was given because someone stood there when it planned, gone since)."""
    here = (float(pose[0]), float(pose[1]))
    if math.dist(here, center) <= tolerance:
        return Ending(ARRIVED, f"arrived at {place}", f"at {place}")
    if math.dist(here, spot) <= tolerance and math.dist(spot, center) >= HERE_M:
        where = f"at a free spot {offset(place, center, here)}"
        if taken_by:
            why = f"{place} is taken by {taken_by}"
        elif fits:
            why = f"{place} was taken when it came"
        else:
            why = f"{place} has no room for it"
        return Ending(FREE_SPOT, f"{where}; {why}", where)
    where = offset(place, center, here)
    return Ending(STOPPED, f"stopped {where}", where)


def robot_line(name: str, status: str, words: str) -> str:
    """One robot's share of an instruction as the answer gives it: "robot1: succeeded (arrived at A)"."""
    return f"{name}: {status}" + (f" ({words})" if words else "")


def turned(asked_deg: float, done_deg: float) -> str:
    """A turn on the spot in words: as asked when it measured within SAID_AS_ASKED_DEG of it, else the measure
    ("turned 104° left (90° left asked)"). Left is anticlockwise (positive)."""

    def amount(degrees: float) -> str:
        return f"{abs(degrees):.0f}° {'left' if degrees >= 0 else 'right'}"

    if abs(done_deg - asked_deg) <= SAID_AS_ASKED_DEG:
        return f"turned {abs(asked_deg):g}° {'left' if asked_deg >= 0 else 'right'}"
    return f"turned {amount(done_deg)} ({amount(asked_deg)} asked)"


def moved(asked_m: float, done_m: float) -> str:
    """A move straight by an amount in words, as turned() says a turn ("moved 1.12 m forward (1 m forward
    asked)")."""

    def amount(metres: float, digits: int = 2) -> str:
        return f"{round(abs(metres), digits):g} m {'forward' if metres >= 0 else 'back'}"

    if abs(done_m - asked_m) <= SAID_AS_ASKED_M:
        return f"moved {amount(asked_m, 3)}"
    return f"moved {amount(done_m)} ({amount(asked_m, 3)} asked)"
