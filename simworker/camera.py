"""A synthetic camera: a small first-person view drawn from rays cast in the physics, encoded as PNG.

Stands in for a robot's head camera (e.g. TIAGo's Xtion, /xtion/rgb/image_raw/compressed) so a camera panel can
be tested without Gazebo: walls and robots in front are drawn as columns whose height falls with their
distance, over a sky and a floor; a block runs along the top edge, one step per frame, so every frame differs.
Plain Python (fleetcore.images writes the PNG): no imaging library.
"""

from __future__ import annotations

from fleetcore.catalog import Laser
from fleetcore.images import png

WIDTH, HEIGHT = 160, 120
RAYS = Laser("camera", "xtion_rgb_optical_frame", 80, -0.5, 0.5, 0.05, 10.0, 2.0)  # 57° across, as the Xtion
SKY, FLOOR, MARK = bytes((205, 225, 245)), bytes((125, 125, 125)), bytes((220, 40, 40))
WALL = (190, 150, 105)


def render(ranges: list[float | None], frame: int) -> bytes:
    """The view for these ranges (RAYS' order: right to left), as one PNG of WIDTH x HEIGHT RGB pixels."""
    per_ray = WIDTH // len(ranges)
    horizon = HEIGHT // 2
    columns = []  # (top, bottom, colour) per image column, left to right
    for distance in reversed(ranges):
        if distance is None:
            top = bottom = horizon
            colour = SKY
        else:
            half = min(horizon, int(HEIGHT * 0.35 / max(distance, 0.1)))
            top, bottom = horizon - half, horizon + half
            shade = 1.0 - min(distance / RAYS.range_max, 0.8)
            colour = bytes(int(c * shade) for c in WALL)
        columns += [(top, bottom, colour)] * per_ray
    mark = (frame * 4) % (WIDTH - 8)
    rows = bytearray()
    for y in range(HEIGHT):
        rows.append(0)  # PNG filter: none
        ground = SKY if y < horizon else FLOOR
        rows += b"".join(colour if top <= y < bottom else ground for top, bottom, colour in columns)
        if 2 <= y < 8:
            start = 1 + y * (WIDTH * 3 + 1) + mark * 3
            rows[start : start + 24] = MARK * 8
    return png(WIDTH, HEIGHT, bytes(rows))
