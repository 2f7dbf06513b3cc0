"""The step contract: what the interpreter emits, `submit` validates, dispatch splits and the executor runs.

A step is one action for some robots: where to (a destination), what to do there (a task such as rotate(3) or
clean), how fast (a speed word), how much (an amount in the unit its action measures: metres for move_by,
degrees for turn_by, seconds for wait, times for repeat) and, for a repeat, how many steps before it it repeats
(span; a repeat without an amount runs until the robot is stopped). Its robots are a `fleetcore.choice.RobotChoice`
(names, all, any, a kind, an exclusion). It travels as a dict (JSON in the database and on the wire) and is checked by
`Step.from_dict`, which raises StepError with a sentence for a person. Speed words live in `fleetcore.speed`:
the interpreter's phrases map onto them and `Step.pace` turns them into the limits each robot is driven at.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from typing import Annotated, TypedDict

from fleetcore import actions
from fleetcore import speed as speeds  # (a Step's field is named speed)
from fleetcore.choice import ChoiceError, RobotChoice, RobotsWire

# Unit words -> (unit, factor to it). The interpreter's phrases of amounts map onto these, the handlers read the
# unit of their action (fleetcore.actions.Action.unit).
UNITS: dict[str, tuple[str, float]] = {
    **dict.fromkeys(("m", "meter", "meters", "metre", "metres", "mtr", "mtrs"), ("m", 1.0)),
    **dict.fromkeys(("cm", "centimeter", "centimeters", "centimetre", "centimetres"), ("m", 0.01)),
    **dict.fromkeys(("mm", "millimeter", "millimeters", "millimetre", "millimetres"), ("m", 0.001)),
    **dict.fromkeys(("ft", "foot", "feet"), ("m", 0.3048)),
    **dict.fromkeys(("deg", "degree", "degrees", "°"), ("deg", 1.0)),
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), ("s", 1.0)),
    **dict.fromkeys(("min", "mins", "minute", "minutes"), ("s", 60.0)),
}
# Direction words -> (unit, sign, the amount meant when none is said; None: ask for it).
DIRECTIONS: dict[str, tuple[str, int, float | None]] = {
    **dict.fromkeys(("forward", "forwards", "ahead", "straight ahead", "onward"), ("m", 1, None)),
    **dict.fromkeys(("back", "backward", "backwards", "in reverse", "rearward"), ("m", -1, None)),
    **dict.fromkeys(
        ("left", "to the left", "anticlockwise", "counterclockwise", "counter clockwise", "anti clockwise"),
        ("deg", 1, 90.0),
    ),
    **dict.fromkeys(("right", "to the right", "clockwise"), ("deg", -1, 90.0)),
    **dict.fromkeys(("around", "round"), ("deg", 1, 180.0)),  # "turn around": face the other way
}
LIMITS: dict[str, float] = {
    "m": 50.0,
    "deg": 3600.0,
    "s": 3600.0,
    "times": 100.0,
}  # the largest amount of each
MAX_SPAN = 200  # steps a repeat may go back over
TASK_RE = re.compile(r"^(?P<name>[a-z_]+)(?:\((?P<count>\d{1,3}(?:\.\d{1,3})?)\))?$")
MAX_COUNT = 100


class StepError(ValueError):
    """A step the executor cannot run; the message says why, for a person."""


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
    yaw: float | None = None  # the heading to end with (rad, map frame), when one was given
    center: tuple[float, float] | None = None  # where the place asked for is (with `around`)
    taken_by: str | None = None  # who took the place (with `around`): "husky", "husky's goal"

    @property
    def place(self) -> tuple[str, tuple[float, float]]:
        """The place asked for and where it is: the destination itself, or the one its free spot is next to."""
        if self.around and self.center is not None:
            return self.around, self.center
        return self.name, (self.x, self.y)

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
        around, yaw = data.get("around"), data.get("yaw")
        if yaw is not None and (
            isinstance(yaw, bool) or not isinstance(yaw, int | float) or not math.isfinite(yaw)
        ):
            raise StepError("a destination's yaw must be a finite number (radians)")
        return cls(
            name,
            x,
            y,
            str(around) if around else None,
            None if yaw is None else float(yaw),
            _point(data.get("center")),
            str(data["taken_by"]) if data.get("taken_by") else None,
        )


def _point(value) -> tuple[float, float] | None:
    """(x, y) from [x, y] of finite numbers; None for anything else (a step written before it was kept)."""
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        return None
    return (x, y) if math.isfinite(x) and math.isfinite(y) else None


# The wire form of a step, declared once: what the interpreter writes (a type III-V step may have no action and
# a destination with no position), what `Step.from_dict` reads and `Step.to_dict` writes, and what the API's schema
# is generated from (portal/interpretation_schema.py; a key's string is its description there). Every writer
# writes the keys of the first class; the second's only when they say something.
class _DestinationKeys(TypedDict):
    name: Annotated[str, "the place's name; a point's is its coordinates"]
    x: Annotated[float | None, "m, map frame; null: a place the interpreter does not know"]
    y: Annotated[float | None, "m, map frame"]


class DestinationWire(_DestinationKeys, total=False):
    """Where to: a place on the map, or a free spot next to it."""

    yaw: Annotated[float | None, "rad, map frame: the heading to end with"]
    around: Annotated[str | None, "the place asked for, when the robot was given a free spot next to it"]
    center: Annotated[list[float] | None, "[x, y] of that place"]
    taken_by: Annotated[str | None, "who took that place: a robot, or a robot's goal"]


class _StepKeys(TypedDict):
    action: Annotated[str | None, "fleetcore.actions; null: a verb not understood (types III-V)"]
    robots: Annotated[RobotsWire, 'names, "all", "any" (null: any), or a kind or an exclusion']
    destination: DestinationWire | None
    task: Annotated[str | None, '"rotate(3)", "clean"']
    speed: Annotated[str | None, "a speed word (fleetcore.speed)"]


class StepWire(_StepKeys, total=False):
    """One action for some robots, as it travels (JSON in the database, the API and the socket)."""

    amount: Annotated[float, "in the unit of the action: m, deg, s, or times for a repeat"]
    span: Annotated[int, "repeat: how many steps before it it repeats"]
    instruction: Annotated[int, 'cancel: the instruction it takes back ("cancel #12")']


@dataclass(frozen=True)
class Step:
    action: str
    robots: RobotChoice
    destination: Destination | None = None
    task: str | None = None
    speed: str | None = None
    amount: float | None = None  # in the unit of the action (Action.unit); None for repeat: until stopped
    span: int | None = None  # repeat: how many steps before it it repeats

    @property
    def spec(self) -> actions.Action:
        return actions.ACTIONS[self.action]

    @property
    def priority(self) -> int:
        """The priority of the step's activity: the state its action puts the robot in (a task: work)."""
        return actions.ACTIONS["clean"].priority if self.task else self.spec.priority

    def pace(self, limits: speeds.Limits) -> speeds.Pace:
        """What this step's speed word asks of a robot with these limits (fleetcore.speed.pace)."""
        return speeds.pace(self.speed, limits)

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
        said = data.get("speed") or None
        try:
            speeds.word(said)
        except speeds.UnknownSpeed as exc:
            raise StepError(str(exc)) from None
        amount, span = _amount(spec, data.get("amount")), _span(spec, data.get("span"))
        return cls(name, _robots(data.get("robots")), destination, task, said, amount, span)

    def to_dict(self) -> dict:
        out = asdict(self)
        out["robots"] = self.robots.to_wire()
        for key in StepWire.__optional_keys__ & out.keys():  # written only when they say something
            if out[key] is None:
                del out[key]
        for key in ("center", "taken_by"):  # (kept only for a free spot next to a place)
            if out["destination"] and out["destination"][key] is None:
                del out["destination"][key]
        return out


_UNIT_WORDS = {"m": "metres", "deg": "degrees", "s": "seconds", "times": "times"}


def _amount(spec: actions.Action, value) -> float | None:
    """The step's amount, checked against its action's unit and the unit's limit."""
    if value is None:
        if spec.unit in ("m", "deg", "s"):
            raise StepError(f"say how much to {spec.name.replace('_', ' ')} (in {_UNIT_WORDS[spec.unit]})")
        return None
    if spec.unit is None:
        raise StepError(f"'{spec.name}' takes no amount")
    try:
        amount = float(value)
    except (TypeError, ValueError):
        raise StepError(f"the amount of '{spec.name}' is a number of {_UNIT_WORDS[spec.unit]}") from None
    limit = LIMITS[spec.unit]
    low = -limit if spec.unit in ("m", "deg") else 0.0
    if not (math.isfinite(amount) and low <= amount <= limit and (amount != 0 or spec.unit in ("m", "deg"))):
        raise StepError(f"'{spec.name}' takes {'more than 0 and ' if low == 0 else ''}up to {limit:g} "
                        f"{_UNIT_WORDS[spec.unit]}, not {value}")  # fmt: skip
    return amount


def _span(spec: actions.Action, value) -> int | None:
    if spec.unit != "times":
        if value is not None:
            raise StepError(f"'{spec.name}' repeats nothing")
        return None
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= MAX_SPAN:
        raise StepError(f"a repeat names how many steps before it it repeats (1 to {MAX_SPAN})")
    return value


def _robots(value) -> RobotChoice:
    try:
        return RobotChoice.of(value)
    except ChoiceError as exc:
        raise StepError(str(exc)) from None


def validate(steps) -> list[Step]:
    """Every step of an instruction, checked; StepError for the first that cannot run."""
    if not isinstance(steps, list) or not steps:
        raise StepError("the instruction has no step a robot can do")
    return [Step.from_dict(step) for step in steps]


def priority(steps: list[dict]) -> int:
    """The priority of one robot's list of steps: the highest of them (0 when there are none)."""
    return max((Step.from_dict(step).priority for step in steps), default=0)
