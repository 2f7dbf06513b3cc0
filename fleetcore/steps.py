"""The step contract: what the interpreter emits, `submit` validates, dispatch splits and the executor runs.

A step is one action for some robots: where to (a destination), what to do there (a task such as rotate(3) or
clean), how fast (a speed word). It travels as a dict (JSON in the database and on the wire) and is checked by
`Step.from_dict`, which raises StepError with a sentence for a person. Speed words live here, once: the
interpreter's phrases map onto them and the executor turns them into a fraction of each robot's limits.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass

from fleetcore import actions

# A speed word -> the fraction of each robot's own velocity limits it asks for. None means "normal".
SPEEDS: dict[str, float] = {"very slow": 0.2, "slow": 0.35, "normal": 0.6, "fast": 0.85, "very fast": 1.0}
DEFAULT_SPEED = "normal"
ALL, ANY = "all", "any"  # every free robot; the one best robot (allocation)
TASK_RE = re.compile(r"^(?P<name>[a-z_]+)(?:\((?P<count>\d{1,3}(?:\.\d{1,3})?)\))?$")
MAX_COUNT = 100


class StepError(ValueError):
    """A step the executor cannot run; the message says why, for a person."""


def speed_factor(word: str | None) -> float:
    """The fraction of a robot's limits a speed word asks for; StepError for a word nobody defined."""
    key = DEFAULT_SPEED if word is None or word == "" else str(word).strip().lower()
    if key not in SPEEDS:
        raise StepError(f"unknown speed {word!r}; say one of: {', '.join(SPEEDS)}")
    return SPEEDS[key]


def parse_task(task: str) -> tuple[str, float]:
    """("rotate", 3) from "rotate(3)" (a quarter turn: "rotate(0.25)"); ("clean", 1) from "clean"; else StepError."""
    match = TASK_RE.match(re.sub(r"\s+", "", str(task or "")).lower())
    spec = actions.ACTIONS.get(match["name"]) if match else None
    if spec is None or spec.category != "task" or (match["count"] and not spec.countable):
        tasks = [
            f"{a.name}(n)" if a.countable else a.name
            for a in actions.ACTIONS.values()
            if a.category == "task"
        ]
        raise StepError(f"unknown task {task!r}; known: {', '.join(tasks)}")
    count = float(match["count"] or 1)
    if not 0 < count <= MAX_COUNT:
        raise StepError(f"a task is repeated more than 0 and up to {MAX_COUNT} times, not {count:g}")
    return match["name"], int(count) if count.is_integer() else count


@dataclass(frozen=True)
class Destination:
    name: str
    x: float
    y: float
    around: str | None = None  # the place asked for, when the robot was given a free spot next to it

    @classmethod
    def from_dict(cls, data) -> Destination:
        if not isinstance(data, dict):
            raise StepError("a destination is an object with a name and x, y")
        try:
            x, y = float(data["x"]), float(data["y"])
        except (KeyError, TypeError, ValueError):
            raise StepError(f"the destination {data.get('name')!r} has no position on the map") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise StepError("a destination's x and y must be finite numbers")
        name = str(data.get("name") or f"({x:g}, {y:g})")
        around = data.get("around")
        return cls(name, x, y, str(around) if around else None)


@dataclass(frozen=True)
class Step:
    action: str
    robots: tuple[str, ...] | str  # names, or ALL, or ANY
    destination: Destination | None = None
    task: str | None = None
    speed: str | None = None

    @property
    def spec(self) -> actions.Action:
        return actions.ACTIONS[self.action]

    @property
    def priority(self) -> int:
        """The priority of the step's activity: the state its action puts the robot in (a task: work)."""
        return actions.ACTIONS["clean"].priority if self.task else self.spec.priority

    @property
    def factor(self) -> float:
        return speed_factor(self.speed)

    @classmethod
    def from_dict(cls, data) -> Step:
        """Check one step as the interpreter (or an API caller) wrote it; StepError says what is wrong."""
        if not isinstance(data, dict):
            raise StepError("a step is an object")
        name = data.get("action") or ("move" if data.get("destination") else None)
        if name is None and data.get("task"):
            name = parse_task(data["task"])[0]
        try:
            spec = actions.get(name)
        except actions.UnknownAction as exc:
            raise StepError(str(exc.args[0])) from None
        destination = Destination.from_dict(data["destination"]) if data.get("destination") else None
        if spec.requires_destination and destination is None:
            raise StepError(f"say where to {name}")
        task = data.get("task") or None
        if task is not None:
            parse_task(task)
        speed = data.get("speed") or None
        speed_factor(speed)
        return cls(name, _robots(data.get("robots")), destination, task, speed)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["robots"] = list(self.robots) if isinstance(self.robots, tuple) else self.robots
        return out

    def for_robot(self, name: str, destination: Destination | None = None) -> Step:
        """This step as one robot's share of it (its own spot, when it was given one)."""
        return Step(self.action, (name,), destination or self.destination, self.task, self.speed)


def _robots(value) -> tuple[str, ...] | str:
    if value in (None, "", ANY):
        return ANY
    if value == ALL:
        return ALL
    if isinstance(value, list | tuple) and not value:
        raise StepError("Say which robot should do it (a name, 'all robots' or 'any robot').")
    if isinstance(value, list | tuple) and all(isinstance(v, str) and v for v in value):
        return tuple(value)
    raise StepError("robots is a list of robot names, 'all' or 'any'")


def validate(steps) -> list[Step]:
    """Every step of an instruction, checked; StepError for the first that cannot run."""
    if not isinstance(steps, list) or not steps:
        raise StepError("the instruction has no step a robot can do")
    return [Step.from_dict(step) for step in steps]


def priority(steps: list[dict]) -> int:
    """The priority of one robot's list of steps: the highest of them (0 when there are none)."""
    return max((Step.from_dict(step).priority for step in steps), default=0)
