"""Path planning on an occupancy grid: A* on the map coarsened to PLAN_CELL, inflated by the robot's radius.

Plain code (numpy, no Django): the simulator's navigation stacks plan with it, and so does the execution engine
for robots without a navigation stack of their own, so that "move to C" goes around the walls between.
"""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np

from fleetcore.mapfile import FREE, OccupancyGrid

PLAN_CELL = 0.1  # planning resolution (m)
AVOID_MARGIN = 0.15  # m kept from a robot the map does not show (cells are coarse; legs cut corners)


class Planner:
    """A* on the map coarsened to PLAN_CELL and inflated by the robot's inscribed radius."""

    def __init__(self, grid: OccupancyGrid, radius: float) -> None:
        self.grid, self.radius = grid, radius
        fine = np.array(grid.data, dtype=np.int16).reshape(grid.height, grid.width) != FREE
        k = max(1, round(PLAN_CELL / grid.resolution))
        h, w = grid.height // k, grid.width // k
        blocked = fine[: h * k, : w * k].reshape(h, k, w, k).any(axis=(1, 3))
        self.k, self.h, self.w = k, h, w
        self.cell = grid.resolution * k
        self.lethal = _dilate(blocked, radius + 0.05, self.cell)
        self.near = _dilate(blocked, radius + 0.35, self.cell)

    def to_cell(self, x: float, y: float) -> tuple[int, int]:
        ox, oy, _ = self.grid.origin
        return int((x - ox) / self.cell), int((y - oy) / self.cell)

    def to_world(self, c: int, r: int) -> tuple[float, float]:
        ox, oy, _ = self.grid.origin
        return ox + (c + 0.5) * self.cell, oy + (r + 0.5) * self.cell

    def free(self, c: int, r: int, blocked: frozenset = frozenset()) -> bool:
        return 0 <= c < self.w and 0 <= r < self.h and not self.lethal[r, c] and (c, r) not in blocked

    def cells_near(self, avoid) -> frozenset:
        """The cells a robot of this planner's size cannot enter near these discs (x, y, radius)."""
        out = set()
        for x, y, radius in avoid:
            c0, r0 = self.to_cell(x, y)
            reach = radius + self.radius + AVOID_MARGIN
            n = math.ceil(reach / self.cell)
            for dc in range(-n, n + 1):
                for dr in range(-n, n + 1):
                    if math.hypot(dc, dr) * self.cell <= reach:
                        out.add((c0 + dc, r0 + dr))
        return frozenset(out)

    def plan(
        self, start: tuple[float, float], goal: tuple[float, float], avoid=()
    ) -> list[tuple[float, float]] | None:
        """Return waypoints from start to goal (ending exactly at goal), or None if unreachable.

        avoid: discs (x, y, radius) the map does not show, e.g. other robots a local costmap would see.
        """
        s, g = self.to_cell(*start), self.to_cell(*goal)
        # A robot pressed against another stands inside that one's inflated disc: let it back out.
        escape = math.ceil((self.radius + AVOID_MARGIN) / self.cell)
        blocked = frozenset(
            c for c in self.cells_near(avoid) if max(abs(c[0] - s[0]), abs(c[1] - s[1])) > escape
        )
        if not self.free(*g, blocked):
            return None
        cells = self._astar(s, g, blocked)
        if cells is None:
            return None
        points = [self.to_world(*c) for c in self._shortcut(cells, blocked)]
        return [*points[1:-1], goal] if len(points) > 1 else [goal]

    def _astar(self, s, g, blocked):
        tie = itertools.count()
        openq = [(0.0, next(tie), s)]
        cost = {s: 0.0}
        parent = {s: None}
        steps = [(dc, dr, math.hypot(dc, dr)) for dc in (-1, 0, 1) for dr in (-1, 0, 1) if dc or dr]
        while openq:
            _, _, cur = heapq.heappop(openq)
            if cur == g:
                path = []
                while cur is not None:
                    path.append(cur)
                    cur = parent[cur]
                return path[::-1]
            base = cost[cur]
            for dc, dr, d in steps:
                nxt = (cur[0] + dc, cur[1] + dr)
                if not self.free(*nxt, blocked) and nxt != g:
                    continue
                new = base + d + (2.0 if self.near[nxt[1], nxt[0]] else 0.0)
                if new < cost.get(nxt, math.inf):
                    cost[nxt] = new
                    parent[nxt] = cur
                    heapq.heappush(openq, (new + math.hypot(g[0] - nxt[0], g[1] - nxt[1]), next(tie), nxt))
        return None

    def _shortcut(self, cells, blocked):
        """Keep only the cells needed for straight, collision-free legs (string pulling)."""
        out, i = [cells[0]], 0
        while i < len(cells) - 1:
            j = len(cells) - 1
            while j > i + 1 and not self._visible(cells[i], cells[j], blocked):
                j -= 1
            out.append(cells[j])
            i = j
        return out

    def _visible(self, a, b, blocked) -> bool:
        n = max(abs(b[0] - a[0]), abs(b[1] - a[1])) * 2
        for t in range(n + 1):
            c = round(a[0] + (b[0] - a[0]) * t / n)
            r = round(a[1] + (b[1] - a[1]) * t / n)
            if not self.free(c, r, blocked) or self.near[r, c]:
                return False
        return True


def _dilate(mask: np.ndarray, radius: float, cell: float) -> np.ndarray:
    """Grow True cells by a disc of the given radius."""
    n = math.ceil(radius / cell)
    out = mask.copy()
    h, w = mask.shape
    for dr in range(-n, n + 1):
        for dc in range(-n, n + 1):
            if (dr * dr + dc * dc) * cell * cell > radius * radius:
                continue
            src = mask[max(0, -dr) : h - max(0, dr), max(0, -dc) : w - max(0, dc)]
            out[max(0, dr) : h - max(0, -dr), max(0, dc) : w - max(0, -dc)] |= src
    return out
