"""ROS map_server map files (YAML + PGM) as an occupancy grid, without Django.

Follows docs/reference/rosbridge_protocol.md section 6: ROS 1 map_server's loader and
map_saver's writer (trinary / scale / raw modes, negate, thresholds, bottom-left origin).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

FREE, OCCUPIED, UNKNOWN = 0, 100, -1
MODES = ("trinary", "scale", "raw")
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")


class MapFormatError(ValueError):
    """A map file that map_server would refuse; the message names the file and the problem."""


@dataclass
class OccupancyGrid:
    """A 2D occupancy grid in ROS order: row-major from the bottom-left cell, values 0/100/-1."""

    resolution: float
    width: int
    height: int
    origin: tuple[float, float, float]
    data: list[int]
    frame_id: str = "map"
    loaded_at: float = field(default_factory=time.time)

    def __post_init__(self) -> None:
        if len(self.data) != self.width * self.height:
            raise MapFormatError(f"grid data has {len(self.data)} cells, expected {self.width}x{self.height}")

    @property
    def size_m(self) -> tuple[float, float]:
        """Return the map's extent in metres (width, height)."""
        return self.width * self.resolution, self.height * self.resolution

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        """Return the (column, row) of the cell holding map-frame point (x, y); may be off the grid."""
        ox, oy, yaw = self.origin
        dx, dy = x - ox, y - oy
        if yaw:
            c, s = math.cos(-yaw), math.sin(-yaw)
            dx, dy = c * dx - s * dy, s * dx + c * dy
        return math.floor(dx / self.resolution), math.floor(dy / self.resolution)

    def cell_to_world(self, col: int, row: int) -> tuple[float, float]:
        """Return the map-frame centre of cell (col, row)."""
        ox, oy, yaw = self.origin
        dx, dy = (col + 0.5) * self.resolution, (row + 0.5) * self.resolution
        if yaw:
            c, s = math.cos(yaw), math.sin(yaw)
            dx, dy = c * dx - s * dy, s * dx + c * dy
        return ox + dx, oy + dy

    def in_bounds(self, col: int, row: int) -> bool:
        """Tell whether (col, row) lies on the grid."""
        return 0 <= col < self.width and 0 <= row < self.height

    def value(self, col: int, row: int) -> int:
        """Return the cell's value; cells off the grid count as unknown."""
        if not self.in_bounds(col, row):
            return UNKNOWN
        return self.data[row * self.width + col]

    def is_free(self, x: float, y: float) -> bool:
        """Tell whether map-frame point (x, y) lies in a known free cell."""
        return self.value(*self.world_to_cell(x, y)) == FREE

    def to_msg(self, ros_version: int = 1, stamp: float | None = None) -> dict:
        """Return the nav_msgs/OccupancyGrid message as rosbridge JSON for ROS 1 or ROS 2."""
        ox, oy, yaw = self.origin
        now = time.time() if stamp is None else stamp
        header = {"stamp": _time(now, ros_version), "frame_id": self.frame_id}
        if ros_version == 1:
            header = {"seq": 0, **header}
        info = {
            "map_load_time": _time(self.loaded_at, ros_version),
            "resolution": self.resolution,
            "width": self.width,
            "height": self.height,
            "origin": {
                "position": {"x": ox, "y": oy, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)},
            },
        }
        return {"header": header, "info": info, "data": list(self.data)}


def _time(t: float, ros_version: int) -> dict:
    """Encode a UNIX time as ROS 1 {secs, nsecs} or ROS 2 {sec, nanosec}."""
    sec = int(t)
    nsec = int((t - sec) * 1e9)
    return {"secs": sec, "nsecs": nsec} if ros_version == 1 else {"sec": sec, "nanosec": nsec}


def load_map(yaml_path: str | Path) -> OccupancyGrid:
    """Load a map_server YAML file and its image into an OccupancyGrid."""
    path = Path(yaml_path)
    meta = _read_yaml(path)
    image = Path(meta["image"])
    if not image.is_absolute():
        image = path.parent / image
    try:
        width, height, maxval, pixels = _read_pgm(image)
    except MapFormatError as exc:
        raise MapFormatError(f"{path}: {exc}") from None
    data = [0] * (width * height)
    convert = _pixel_converter(meta, maxval)
    for j in range(height):
        base = width * (height - 1 - j)
        row = pixels[j * width : (j + 1) * width]
        for i, px in enumerate(row):
            data[base + i] = convert(px)
    origin = tuple(float(v) for v in meta["origin"])
    return OccupancyGrid(float(meta["resolution"]), width, height, origin, data)


def _read_yaml(path: Path) -> dict:
    """Read and validate the map YAML; raise MapFormatError naming the problem."""
    try:
        meta = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise MapFormatError(f"{path}: cannot read ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0]
        raise MapFormatError(f"{path}: not valid YAML ({first})") from exc
    if not isinstance(meta, dict):
        raise MapFormatError(f"{path}: expected a mapping of map keys")
    missing = [k for k in REQUIRED_KEYS if k not in meta]
    if missing:
        raise MapFormatError(f"{path}: missing key(s) {', '.join(missing)}")
    if not isinstance(meta["image"], str) or not meta["image"]:
        raise MapFormatError(f"{path}: 'image' must be a non-empty path")
    origin = meta["origin"]
    if not isinstance(origin, list) or len(origin) != 3 or not all(_is_num(v) for v in origin):
        raise MapFormatError(f"{path}: 'origin' must be [x, y, yaw]")
    for key in ("resolution", "occupied_thresh", "free_thresh"):
        if not _is_num(meta[key]):
            raise MapFormatError(f"{path}: '{key}' must be a number, got {meta[key]!r}")
    if meta["resolution"] <= 0:
        raise MapFormatError(f"{path}: 'resolution' must be positive")
    if meta["negate"] not in (0, 1, True, False):
        raise MapFormatError(f"{path}: 'negate' must be 0 or 1, got {meta['negate']!r}")
    meta.setdefault("mode", "trinary")
    if meta["mode"] not in MODES:
        raise MapFormatError(f"{path}: 'mode' must be one of {', '.join(MODES)}")
    return meta


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _pixel_converter(meta: dict, maxval: int):
    """Return a function mapping a grey pixel value to a cell value, per map_server."""
    negate, mode = bool(meta["negate"]), meta["mode"]
    occ_t, free_t = float(meta["occupied_thresh"]), float(meta["free_thresh"])

    def convert(px: int) -> int:
        avg = px * 255 // maxval if maxval != 255 else px
        if mode == "raw":
            return avg
        occ = avg / 255.0 if negate else (255 - avg) / 255.0
        if occ > occ_t:
            return OCCUPIED
        if occ < free_t:
            return FREE
        if mode == "scale":
            return int(1 + 98 * (occ - free_t) / (occ_t - free_t))
        return UNKNOWN

    return convert


def _read_pgm(path: Path) -> tuple[int, int, int, bytes]:
    """Read a binary (P5) or ASCII (P2) PGM; return width, height, maxval and top-first pixels."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise MapFormatError(f"cannot read image {path} ({exc.strerror})") from exc
    magic = raw[:2]
    if magic not in (b"P5", b"P2"):
        raise MapFormatError(f"image {path.name} is not a PGM image (magic {magic!r}, expected P5 or P2)")
    tokens, pos = _pgm_header(raw, path)
    width, height, maxval = tokens
    if width <= 0 or height <= 0 or not 0 < maxval < 256:
        raise MapFormatError(f"image {path.name}: unsupported PGM size {width}x{height} maxval {maxval}")
    n = width * height
    pixels = raw[pos : pos + n] if magic == b"P5" else bytes(int(t) for t in raw[pos:].split()[:n])
    if len(pixels) != n:
        raise MapFormatError(f"image {path.name}: truncated PGM ({len(pixels)} of {n} pixels)")
    return width, height, maxval, pixels


def _pgm_header(raw: bytes, path: Path) -> tuple[list[int], int]:
    """Parse the three header numbers after the magic, skipping comments."""
    tokens: list[int] = []
    pos = 2
    while len(tokens) < 3:
        while pos < len(raw) and raw[pos : pos + 1].isspace():
            pos += 1
        if raw[pos : pos + 1] == b"#":
            pos = raw.find(b"\n", pos) + 1 or len(raw)
            continue
        end = pos
        while end < len(raw) and raw[end : end + 1].isdigit():
            end += 1
        if end == pos:
            raise MapFormatError(f"image {path.name}: malformed PGM header")
        tokens.append(int(raw[pos:end]))
        pos = end
    return tokens, pos + 1


def save_map(
    grid: OccupancyGrid,
    yaml_path: str | Path,
    free_thresh: float = 0.196,
    occupied_thresh: float = 0.65,
) -> None:
    """Write the grid as map_saver does: a trinary P5 PGM beside a YAML of the same stem."""
    path = Path(yaml_path)
    image = path.with_suffix(".pgm")
    t_free, t_occ = 25, 65  # map_saver's threshold_free / threshold_occupied (percent)
    out = bytearray(grid.width * grid.height)
    for j in range(grid.height):
        row = grid.height - 1 - j
        src = grid.data[row * grid.width : (row + 1) * grid.width]
        dst = j * grid.width
        for i, v in enumerate(src):
            out[dst + i] = 254 if 0 <= v <= t_free else (0 if v >= t_occ else 205)
    header = f"P5\n# CREATOR: map_saver.cpp {grid.resolution:.3f} m/pix\n{grid.width} {grid.height}\n255\n"
    image.write_bytes(header.encode() + bytes(out))
    ox, oy, yaw = grid.origin
    path.write_text(
        f"image: {image.name}\nresolution: {grid.resolution:.6f}\n"
        f"origin: [{ox:.6f}, {oy:.6f}, {yaw:.6f}]\nnegate: 0\n"
        f"occupied_thresh: {occupied_thresh}\nfree_thresh: {free_thresh}\n\n"
    )
