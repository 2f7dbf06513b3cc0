"""The traffic grid and who holds which cell when (plain code, no Django): the space-time reservation table.

The world is cut into TRAFFIC_CELL squares; a robot occupies every cell its disc reaches (`footprint_cells`), and
a timed straight leg holds the cells it sweeps for the time it is in them, widened by a slack (`leg_slots`). The
table keeps those holds per cell ({cell: [(t0, t1, robot), ...]}, t1 FOREVER for a robot parked at its goal);
`Spans` and `Busy` are its merged, sorted views that the planner (`fleetcore.traffic.SpaceTimeSearch`) reads
while searching. Time is in seconds on one clock shared by everyone who reserves (the execution engine uses
wall time). Kept apart from the planner: this is the shared schedule, the planner one reader and writer of it.
"""

from __future__ import annotations

import bisect
import functools
import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

TRAFFIC_CELL = 0.2  # m: the reservation table's grid
FOREVER = math.inf

Point = tuple[float, float]
Cell = tuple[int, int]


@functools.cache
def disc_offsets(radius: float, cell: float = TRAFFIC_CELL) -> tuple[Cell, ...]:
    """The cell offsets a disc of this radius centred in a cell may touch (cells whose square it reaches)."""
    n = math.ceil(radius / cell) + 1
    out = []
    for dc in range(-n, n + 1):
        for dr in range(-n, n + 1):
            gap_x, gap_y = max(0.0, (abs(dc) - 0.5) * cell), max(0.0, (abs(dr) - 0.5) * cell)
            if math.hypot(gap_x, gap_y) <= radius:
                out.append((dc, dr))
    return tuple(out)


def cell_of(point: Point, cell: float = TRAFFIC_CELL) -> Cell:
    return math.floor(point[0] / cell), math.floor(point[1] / cell)


def center_of(c: Cell, cell: float = TRAFFIC_CELL) -> Point:
    return (c[0] + 0.5) * cell, (c[1] + 0.5) * cell


def footprint_cells(point: Point, radius: float) -> set[Cell]:
    """Every cell a robot of this radius standing at point touches (its disc reaches the cell's square),
    wherever in its cell the point lies. (Taken as a disc at the cell's centre, a point near a corner
    reached 0.14 m past the cells counted: two plans whose cells never met passed up to 0.28 m nearer
    than their radii.)"""
    x, y = point
    out = set()
    for col in range(math.floor((x - radius) / TRAFFIC_CELL), math.floor((x + radius) / TRAFFIC_CELL) + 1):
        gap_x = max(col * TRAFFIC_CELL - x, 0.0, x - (col + 1) * TRAFFIC_CELL)
        for row in range(
            math.floor((y - radius) / TRAFFIC_CELL), math.floor((y + radius) / TRAFFIC_CELL) + 1
        ):
            gap_y = max(row * TRAFFIC_CELL - y, 0.0, y - (row + 1) * TRAFFIC_CELL)
            if gap_x * gap_x + gap_y * gap_y <= radius * radius:
                out.add((col, row))
    return out


def swept_cells(a: Point, b: Point, radius: float, step: float = TRAFFIC_CELL / 2) -> set[Cell]:
    """Every cell a robot of this radius touches driving the straight leg from a to b."""
    n = max(1, math.ceil(math.dist(a, b) / step))
    out: set[Cell] = set()
    for i in range(n + 1):
        out |= footprint_cells((a[0] + (b[0] - a[0]) * i / n, a[1] + (b[1] - a[1]) * i / n), radius)
    return out


@dataclass
class ReservationTable:
    """Who holds which cell when: {cell: [(t0, t1, robot), ...]}; t1 may be FOREVER (parked at its goal)."""

    cells: dict[Cell, list[tuple[float, float, str]]] = field(default_factory=dict)

    def reserve(self, robot: str, cells: Iterable[Cell], t0: float, t1: float) -> None:
        for c in cells:
            self.cells.setdefault(c, []).append((t0, t1, robot))

    def release(self, robot: str) -> None:
        for c in list(self.cells):
            kept = [entry for entry in self.cells[c] if entry[2] != robot]
            if kept:
                self.cells[c] = kept
            else:
                del self.cells[c]

    def holder(self, cells: Iterable[Cell], t0: float, t1: float, robot: str = "") -> str | None:
        """Someone else holding any of these cells at a time overlapping [t0, t1]; None when all are free."""
        for c in cells:
            for a, b, who in self.cells.get(c, ()):
                if who != robot and a < t1 and t0 < b:
                    return who
        return None

    def intervals(self, robot: str = "") -> Busy:
        """Everyone else's reservations merged per cell, for fast look-ups while searching."""
        return Busy(
            {
                c: [(a, b) for a, b, who in entries if who != robot]
                for c, entries in self.cells.items()
                if any(who != robot for _, _, who in entries)
            }
        )

    def reserve_path(
        self, robot: str, path: Sequence[tuple[float, float, float]], radius: float, pad
    ) -> None:
        """Reserve a timed path [(x, y, t), ...]: each stretch of each leg at the time the robot passes it,
        padded by pad(t). Where it then stays is not a cell reservation: give it to later planners as a
        standing disc from its arrival on (SpaceTimeSearch.plan's `standing`), which is exact."""
        for a, b in itertools.pairwise(path):
            for cells, t0, t1 in leg_slots(a, b, radius, pad):
                self.reserve(robot, cells, t0, t1)

    def leg_free(self, a, b, radius: float, pad, robot: str = "") -> bool:
        """Whether the timed leg a -> b ((x, y, t) each) meets nobody else's reservation."""
        return all(
            self.holder(cells, t0, t1, robot) is None for cells, t0, t1 in leg_slots(a, b, radius, pad)
        )


class Spans:
    """Sorted, disjoint time intervals (overlapping ones merged): when something is held."""

    def __init__(self, intervals: Iterable[tuple[float, float]]) -> None:
        merged: list[list[float]] = []
        for a, b in sorted(intervals):
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        self.starts = [a for a, _ in merged]
        self.ends = [b for _, b in merged]

    def overlaps(self, lo: float, hi: float) -> bool:
        """Whether some interval overlaps (lo, hi)."""
        i = bisect.bisect_right(self.ends, lo)  # the first interval still going on after lo
        return i < len(self.ends) and self.starts[i] < hi

    def pairs(self) -> list[tuple[float, float]]:
        return list(zip(self.starts, self.ends, strict=True))

    def gap_at(self, t: float) -> int | None:
        """The index of the gap (the free time between two intervals) t lies in; None when t is held. Gap i
        runs from the end of interval i - 1 to the start of interval i."""
        i = bisect.bisect_right(self.ends, t)
        return i if i == len(self.starts) or self.starts[i] > t else None

    def gap_end(self, i: int) -> float:
        return self.starts[i] if i < len(self.starts) else FOREVER

    def free_from(self, t: float, duration: float) -> float:
        """The earliest time from t on that begins `duration` seconds free of every interval."""
        i = bisect.bisect_right(self.ends, t)
        while i < len(self.starts) and self.starts[i] < t + duration:
            t, i = self.ends[i], i + 1
        return t


class Busy:
    """When each cell is held by someone (ReservationTable.intervals), and when any of a set of cells is."""

    def __init__(self, held: dict[Cell, list[tuple[float, float]]]) -> None:
        self.cells = {c: Spans(intervals) for c, intervals in held.items()}

    def union(self, cells: Iterable[Cell]) -> Spans:
        """When any of these cells is held (a footprint's: one look-up for it, then, instead of one per cell)."""
        return Spans(
            (a, b)
            for c in cells
            if c in self.cells
            for a, b in zip(self.cells[c].starts, self.cells[c].ends, strict=True)
        )


def leg_slots(a, b, radius: float, pad, step: float = TRAFFIC_CELL):
    """(cells, t0, t1) along a timed straight leg: the footprint over each stretch of `step` metres, for the
    time the robot is in that stretch at constant speed, widened by pad(t)."""
    (x0, y0, ta), (x1, y1, tb) = a, b
    n = max(1, math.ceil(math.dist((x0, y0), (x1, y1)) / step))
    for i in range(n):
        p, q = (
            (x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n),
            (
                x0 + (x1 - x0) * (i + 1) / n,
                y0 + (y1 - y0) * (i + 1) / n,
            ),
        )
        t0, t1 = ta + (tb - ta) * i / n, ta + (tb - ta) * (i + 1) / n
        yield swept_cells(p, q, radius), t0 - pad(t0), t1 + pad(t1)
