"""Draw the `paper` world's map (walls, four rooms, obstacles) and save it as map.yaml + map.pgm.

Run `python -m fleetcore.worlds.make_paper_map` after changing a rectangle; the output is committed.
"""

from __future__ import annotations

from pathlib import Path

from fleetcore.mapfile import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, save_map

RESOLUTION = 0.05
HALF = 6.5  # the image spans -6.5..6.5 m; the walls enclose -6.0..6.0 m
WALL = 0.15
INNER = 6.0

# Rooms sit in the corners beyond |x|, |y| >= 3: a solid wall along y = +-3 and a wall along x = +-3
# with a 2 m doorway (|y| from 3.6 to 5.6), wide enough for the Husky's footprint.
ROOM_WALLS = [
    rect
    for sx in (1, -1)
    for sy in (1, -1)
    for rect in (
        (sorted((sx * 3.0, sx * INNER)), sorted((sy * 2.95, sy * 3.05))),
        (sorted((sx * 2.95, sx * 3.05)), sorted((sy * 3.0, sy * 3.6))),
        (sorted((sx * 2.95, sx * 3.05)), sorted((sy * 5.6, sy * INNER))),
    )
]
OBSTACLES = [
    ((1.4, 2.6), (0.1, 0.5)),  # a crate between the Husky's start and A(2, 2)
    ((-3.25, -2.75), (0.75, 1.25)),  # a pillar west of I(-1, 1)
    ((4.2, 5.6), (-0.4, 0.0)),  # a shelf on the east side
]


def build() -> OccupancyGrid:
    """Return the grid: unknown outside the walls, free inside, occupied walls and obstacles."""
    n = round(2 * HALF / RESOLUTION)
    grid = OccupancyGrid(RESOLUTION, n, n, (-HALF, -HALF, 0.0), [UNKNOWN] * (n * n))
    _fill(grid, (-INNER - WALL, INNER + WALL), (-INNER - WALL, INNER + WALL), OCCUPIED)
    _fill(grid, (-INNER, INNER), (-INNER, INNER), FREE)
    for xs, ys in ROOM_WALLS + OBSTACLES:
        _fill(grid, xs, ys, OCCUPIED)
    return grid


def _fill(grid: OccupancyGrid, xs, ys, value: int) -> None:
    """Set every cell whose centre lies in the rectangle xs x ys."""
    for row in range(grid.height):
        for col in range(grid.width):
            x, y = grid.cell_to_world(col, row)
            if xs[0] <= x <= xs[1] and ys[0] <= y <= ys[1]:
                grid.data[row * grid.width + col] = value


if __name__ == "__main__":
    save_map(build(), Path(__file__).parent / "paper" / "map.yaml")
