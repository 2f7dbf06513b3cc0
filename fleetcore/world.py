"""Worlds: a map_server map plus a small YAML naming locations, robots, endpoints and schedules."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from fleetcore.mapfile import MapFormatError, OccupancyGrid, load_map

WORLDS_DIR = Path(__file__).parent / "worlds"
HHMM = re.compile(r"^([01]\d|2[0-3]):[0-5]\d$")


class WorldFormatError(ValueError):
    """A world file that cannot be used; the message names the file and the problem."""


@dataclass(frozen=True)
class LocationSpec:
    name: str
    x: float
    y: float
    yaw: float = 0.0
    kind: str = "waypoint"  # "waypoint" or "room"


@dataclass(frozen=True)
class RobotSpec:
    name: str
    model: str
    endpoint: str
    namespace: str
    x: float
    y: float
    yaw: float = 0.0
    stack: str = ""  # "", "move_base" (ROS 1) or "nav2" (ROS 2)
    dock: tuple[float, float, float] | None = None  # (x, y, yaw) of its dock station; None: it has none

    @property
    def home(self) -> tuple[float, float, float]:
        """Where the robot belongs: its dock if it has one, else its start pose."""
        return self.dock if self.dock is not None else (self.x, self.y, self.yaw)


@dataclass(frozen=True)
class EndpointSpec:
    key: str
    port_offset: int
    ros_version: int = 1


@dataclass(frozen=True)
class SlotSpec:
    robot: str
    start: str
    end: str
    goal: str
    task: str = ""


@dataclass
class World:
    name: str
    map: OccupancyGrid
    locations: list[LocationSpec]
    robots: list[RobotSpec]
    endpoints: list[EndpointSpec]
    schedules: list[SlotSpec]
    extra: dict = field(default_factory=dict)

    def endpoint(self, key: str) -> EndpointSpec:
        """Return the endpoint with this key."""
        for ep in self.endpoints:
            if ep.key == key:
                return ep
        raise KeyError(f"world {self.name!r} has no endpoint {key!r}")

    def robot_endpoint_urls(self, host: str, port_base: int) -> list[str]:
        """The rosbridge URLs of the endpoints that carry robots, as the simulator serves them from port_base."""
        used = {r.endpoint for r in self.robots}
        return [f"ws://{host}:{port_base + ep.port_offset}" for ep in self.endpoints if ep.key in used]

    def location(self, name: str) -> LocationSpec:
        """Return the location with this name."""
        for loc in self.locations:
            if loc.name == name:
                return loc
        raise KeyError(f"world {self.name!r} has no location {name!r}")

    def add_extra_robots(self, count: int, skip: int = 0, spacing: float | None = None) -> list[RobotSpec]:
        """Place `count` more namespaced robots on free cells of a grid and return them.

        `skip` leaves out the first robots (names and cells) so that simulator shards, each serving its own
        slice, together place the robots one world with all of them would: no name nor cell served twice.
        `spacing` (m) overrides the world's grid, to pack more robots (shards given the same one agree).
        """
        cfg = self.extra
        if count <= 0:
            return []
        if not cfg:
            raise WorldFormatError(f"world {self.name!r} has no 'extra' section for extra robots")
        spots = _free_spots(self, float(spacing or cfg.get("spacing", 0.45)))
        if skip < 0:
            raise WorldFormatError(f"extra robots to skip must be 0 or more, not {skip}")
        if skip + count > len(spots):
            raise WorldFormatError(
                f"world {self.name!r} fits at most {len(spots)} extra robots, not {skip} + {count}"
            )
        first = int(cfg.get("first_index", 1)) + skip
        added = [
            RobotSpec(f"robot{first + i}", cfg["model"], cfg["endpoint"], f"/robot{first + i}", x, y, 0.0)
            for i, (x, y) in enumerate(spots[skip : skip + count])
        ]
        self.robots.extend(added)
        return added


def _free_spots(world: World, spacing: float) -> list[tuple[float, float]]:
    """Return grid points whose surroundings are free and far enough from every placed robot."""
    grid = world.map
    w, h = grid.size_m
    ox, oy, _ = grid.origin
    margin = spacing / 2
    taken = [(r.x, r.y) for r in world.robots] + [r.dock[:2] for r in world.robots if r.dock]
    spots = []
    y = oy + spacing
    while y < oy + h - spacing:
        x = ox + spacing
        while x < ox + w - spacing:
            clear = all(
                grid.is_free(x + dx, y + dy) for dx in (-margin, 0, margin) for dy in (-margin, 0, margin)
            )
            if clear and all((x - tx) ** 2 + (y - ty) ** 2 > 1.0 for tx, ty in taken):
                spots.append((round(x, 3), round(y, 3)))
            x += spacing
        y += spacing
    return spots


def world_path(name_or_path: str | Path) -> Path:
    """Resolve a world name (under fleetcore/worlds) or a path to its world.yaml."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        return path
    if path.is_dir():
        return path / "world.yaml"
    return WORLDS_DIR / str(name_or_path) / "world.yaml"


def load_world(name_or_path: str | Path) -> World:
    """Load a world by name or path; raise WorldFormatError on a bad file."""
    path = world_path(name_or_path)
    try:
        raw = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise WorldFormatError(f"{path}: cannot read world ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise WorldFormatError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from exc
    if not isinstance(raw, dict) or "map" not in raw:
        raise WorldFormatError(f"{path}: expected a mapping with at least a 'map' key")
    try:
        grid = load_map(path.parent / raw["map"])
        world = World(
            name=str(raw.get("name", path.parent.name)),
            map=grid,
            locations=[LocationSpec(**_num(loc, "x", "y", "yaw")) for loc in raw.get("locations", [])],
            robots=[_robot(r) for r in raw.get("robots", [])],
            endpoints=[EndpointSpec(**e) for e in raw.get("endpoints", [])],
            schedules=[SlotSpec(**s) for s in raw.get("schedules", [])],
            extra=dict(raw.get("extra") or {}),
        )
    except MapFormatError:
        raise
    except (TypeError, ValueError) as exc:
        raise WorldFormatError(f"{path}: {exc}") from exc
    _check(world, path)
    return world


def _num(entry: dict, *keys: str) -> dict:
    """Return the entry with the named keys converted to float."""
    out = dict(entry)
    for k in keys:
        if k in out:
            out[k] = float(out[k])
    return out


def _robot(entry: dict) -> RobotSpec:
    out = _num(entry, "x", "y", "yaw")
    out.setdefault("namespace", "")
    if "dock" in out:
        out["dock"] = _dock(out, out["dock"])
    return RobotSpec(**out)


def _dock(robot: dict, dock) -> tuple[float, float, float]:
    """Return a robot's `dock: {x, y, yaw}` as a pose; a key left out takes the robot's start value."""
    name = robot.get("name", "?")
    if not isinstance(dock, dict):
        raise ValueError(f"robot {name!r}: dock must be a mapping {{x, y, yaw}}, not {dock!r}")
    unknown = set(dock) - {"x", "y", "yaw"}
    if unknown:
        raise ValueError(f"robot {name!r}: dock has unknown keys {sorted(unknown)} (allowed: x, y, yaw)")
    start = {"x": robot.get("x"), "y": robot.get("y"), "yaw": robot.get("yaw", 0.0)}
    try:
        return tuple(float(dock.get(k, start[k])) for k in ("x", "y", "yaw"))
    except (TypeError, ValueError):
        raise ValueError(f"robot {name!r}: dock x, y and yaw must be numbers, got {dock!r}") from None


def _check(world: World, path: Path) -> None:
    """Check cross references: endpoints, schedule robots and goals, times, robots on free cells."""
    keys = {e.key for e in world.endpoints}
    names = {r.name for r in world.robots}
    places = {loc.name for loc in world.locations}
    for r in world.robots:
        if r.endpoint not in keys:
            raise WorldFormatError(f"{path}: robot {r.name!r} uses unknown endpoint {r.endpoint!r}")
        if not world.map.is_free(r.x, r.y):
            raise WorldFormatError(f"{path}: robot {r.name!r} starts on a cell that is not free")
        if r.dock is not None and not world.map.is_free(*r.dock[:2]):
            raise WorldFormatError(f"{path}: robot {r.name!r} has its dock on a cell that is not free")
        if r.dock is not None and r.stack != "nav2":
            raise WorldFormatError(
                f"{path}: robot {r.name!r} has a dock but stack {r.stack!r}: the docking action"
                " (irobot_create_msgs/action/Dock) needs a ROS 2 robot with stack nav2"
            )
    for s in world.schedules:
        if s.robot not in names or s.goal not in places:
            raise WorldFormatError(f"{path}: schedule names unknown robot {s.robot!r} or goal {s.goal!r}")
        if not (HHMM.match(s.start) and HHMM.match(s.end)) or s.start >= s.end:
            raise WorldFormatError(f"{path}: bad time slot {s.start}-{s.end} for {s.robot}")
