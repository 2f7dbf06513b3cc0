"""ROS message definitions (simworker/msgdefs) and what rosbridge_server does with a message of a type.

`registry(ros_version)` reads the .msg/.srv/.action text once per flavour. A `Registry` resolves both ROS 1
(`pkg/Name`) and ROS 2 (`pkg/msg/Name`, `pkg/srv/Name`) names, completes a client's message with the type's
defaults and drops it, with the real server's exception text, where rosbridge_library's `populate_instance`
(message_conversion.py, `ros1` and `ros2` branches) would raise. A type it does not know is passed on as sent.
"""

from __future__ import annotations

import ast
import base64
import binascii
import functools
import re
import time
from dataclasses import dataclass
from pathlib import Path

DEFS = Path(__file__).with_name("msgdefs")
INTS = {
    "int8": (-(2**7), 2**7), "uint8": (0, 2**8), "int16": (-(2**15), 2**15), "uint16": (0, 2**16),
    "int32": (-(2**31), 2**31), "uint32": (0, 2**32), "int64": (-(2**63), 2**63), "uint64": (0, 2**64),
    "byte": (0, 2**8), "char": (0, 2**8),
}  # fmt: skip
FLOATS = {"float32", "float64"}
PRIMITIVES = set(INTS) | FLOATS | {"bool", "string"}
IDL = {"float64": "double", "float32": "float", "bool": "boolean", "byte": "octet", "char": "uint8"}
TIMES = {"builtin_interfaces/Time": "time", "builtin_interfaces/Duration": "duration"}
HEADER = "std_msgs/Header"
FIELD_LINE = re.compile(r"^(?P<type>[\w/]+(?:<=\d+)?)(?P<array>\[(?:<=)?\d*\])?\s+(?P<name>\w+)(?P<rest>.*)$")


class ConversionError(Exception):
    """A message rosbridge_server would not publish; the text is the real server's exception text, kind the
    name of the exception class it raises (call_service's log line names it)."""

    def __init__(self, text: str, kind: str = "FieldTypeMismatchException") -> None:
        super().__init__(text)
        self.kind = kind


@dataclass(frozen=True)
class Field:
    name: str
    type: str  # a primitive, "time"/"duration" (ROS 1), or "pkg/Name"
    array: int | None = None  # None: one value; 0: a sequence; N: exactly N
    default: object = None

    @property
    def binary(self) -> bool:
        """uint8[] and char[]: base64 strings on the wire, as rosbridge encodes them."""
        return self.array is not None and self.type in ("uint8", "char")


@dataclass(frozen=True)
class MsgDef:
    name: str  # "pkg/Name" (a service part: "pkg/Name_Request" on ROS 2, "pkg/NameRequest" on ROS 1)
    fields: tuple[Field, ...]
    constants: tuple[tuple[str, str, object], ...]  # (type, name, value)

    def field(self, name: str) -> Field | None:
        return next((f for f in self.fields if f.name == name), None)


@functools.cache
def registry(ros_version: int) -> Registry:
    """The definitions of simworker/msgdefs as an endpoint of this ROS version reads them."""
    return Registry(ros_version)


def base_name(type_: str) -> str:
    """`pkg/msg/Name`, `pkg/srv/Name` or `pkg/Name` -> `pkg/Name`."""
    parts = type_.strip("/").split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) >= 2 else type_


class Registry:
    """Message and service definitions for one ROS version, parsed on first use."""

    def __init__(self, ros_version: int) -> None:
        self.ros_version = ros_version
        self._msgs: dict[str, MsgDef | None] = {}
        self._srvs: dict[str, tuple[MsgDef, MsgDef] | None] = {}

    # ----- lookup -----
    def message(self, type_: str) -> MsgDef | None:
        """The definition of a message type (ROS 1 or ROS 2 spelling), None if unknown."""
        name = base_name(type_)
        if name not in self._msgs:
            self._msgs[name] = self._load_message(name)
        return self._msgs[name]

    def service(self, type_: str) -> tuple[MsgDef, MsgDef] | None:
        """(request, response) definitions of a service type, None if unknown."""
        name = base_name(type_)
        if name not in self._srvs:
            pkg, short = name.split("/", 1) if "/" in name else ("", name)
            path = DEFS / pkg / "srv" / f"{short}.srv"
            self._srvs[name] = None
            if path.is_file():
                request, response = _parts(path.read_text(), 2)
                req, resp = ("_Request", "_Response") if self.ros_version == 2 else ("Request", "Response")
                self._srvs[name] = (self._parse(name + req, request), self._parse(name + resp, response))
        return self._srvs[name]

    def type_name(self, type_: str, kind: str = "msg") -> str:
        """The name the graph reports: `pkg/Name` on ROS 1, `pkg/<kind>/Name` on ROS 2."""
        pkg, _, short = base_name(type_).partition("/")
        return f"{pkg}/{short}" if self.ros_version == 1 else f"{pkg}/{kind}/{short}"

    def _load_message(self, name: str) -> MsgDef | None:
        pkg, _, short = name.partition("/")
        path = DEFS / pkg / "msg" / f"{short}.msg"
        if path.is_file():
            return self._parse(name, path.read_text())
        return self._action_part(pkg, short)

    def _action_part(self, pkg: str, short: str) -> MsgDef | None:
        """Goal/Result/Feedback of a .action (ROS 2: X_Goal, ROS 1: XGoal) and ROS 1's actionlib wrappers."""
        ros1 = self.ros_version == 1
        for index, suffix in enumerate(("Goal", "Result", "Feedback")):
            action = short.removesuffix("Action" + suffix)
            if ros1 and action != short and _action_text(pkg, action):
                return self._ros1_action_wrapper(pkg, short, action, suffix)
            tail = suffix if ros1 else "_" + suffix
            if short.endswith(tail) and (parts := _action_text(pkg, short.removesuffix(tail))):
                return self._parse(f"{pkg}/{short}", parts[index])
        action = short.removesuffix("Action")
        if ros1 and action != short and _action_text(pkg, action):
            text = "\n".join(
                f"{pkg}/{action}Action{s} action_{s.lower()}" for s in ("Goal", "Result", "Feedback")
            )
            return self._parse(f"{pkg}/{short}", text)
        return None

    def _ros1_action_wrapper(self, pkg: str, short: str, action: str, suffix: str) -> MsgDef:
        """ROS 1 genaction's XActionGoal / XActionResult / XActionFeedback."""
        head = "Header header\n"
        if suffix == "Goal":
            body = f"actionlib_msgs/GoalID goal_id\n{pkg}/{action}Goal goal\n"
        else:
            body = f"actionlib_msgs/GoalStatus status\n{pkg}/{action}{suffix} {suffix.lower()}\n"
        return self._parse(f"{pkg}/{short}", head + body)

    # ----- parsing -----
    def _parse(self, name: str, text: str) -> MsgDef:
        pkg = name.split("/", 1)[0]
        fields, constants = [], []
        if self.ros_version == 1 and name == HEADER:
            fields.append(Field("seq", "uint32"))
        for raw in text.splitlines():
            line = _strip_comment(raw).strip()
            match = FIELD_LINE.match(line)
            if not match:
                continue
            type_ = self._resolve(match["type"], pkg)
            rest = match["rest"].strip()
            if rest.startswith("="):
                constants.append((type_, match["name"], _literal(type_, rest[1:].strip(), constant=True)))
                continue
            array = match["array"]
            size = None if array is None else int(array.strip("[]<=") or 0) if "<=" not in array else 0
            default = _literal(type_, rest, array is not None) if rest else None
            fields.append(Field(match["name"], type_, size, default))
        return MsgDef(name, tuple(fields), tuple(constants))

    def _resolve(self, type_: str, pkg: str) -> str:
        type_ = type_.split("<=", 1)[0]  # a bounded string is a string here
        if type_ in PRIMITIVES or type_ in ("time", "duration"):
            return type_
        if type_ == "Header":
            type_ = HEADER
        elif "/" not in type_:
            type_ = f"{pkg}/{type_}"
        if self.ros_version == 1 and type_ in TIMES:
            return TIMES[type_]
        return type_

    # ----- defaults -----
    def default(self, definition: MsgDef) -> dict:
        """A message of this definition with every field at its default."""
        return {f.name: self._field_default(f) for f in definition.fields}

    def _field_default(self, field: Field):
        if field.default is not None:
            value = list(field.default) if isinstance(field.default, list) else field.default
            return self.wire_array(field, value) if field.array is not None else value
        if field.array is not None:
            values = [self._scalar_default(field)] * field.array if field.array else []
            return self.wire_array(field, values)
        return self._scalar_default(field)

    def _scalar_default(self, field: Field):
        type_ = field.type
        if type_ in FLOATS:
            return 0.0
        if type_ in INTS:
            return 0
        if type_ == "bool":
            return False
        if type_ == "string":
            return ""
        if type_ in ("time", "duration"):
            return {"secs": 0, "nsecs": 0}
        if type_ in TIMES:
            return {"sec": 0, "nanosec": 0}
        sub = self.message(type_)
        return self.default(sub) if sub is not None else {}

    def wire_array(self, field: Field, values: list):
        """uint8[]/char[] go out base64-encoded, as rosbridge's extract_values sends them."""
        if field.binary:
            return base64.b64encode(bytes(values)).decode("ascii")
        return values

    # ----- rosapi's typedefs -----
    def typedefs(self, definition: MsgDef | None, seen: set[str] | None = None) -> list[dict]:
        """rosapi objectutils' recursive typedefs: this definition's, then each field type's not yet seen."""
        if definition is None:
            return []
        seen = seen if seen is not None else {definition.name}
        out = [self.typedef(definition)]
        for field in definition.fields:
            name = self._typedef_type(field)
            if name in seen or name in PRIMITIVES or name in IDL.values():
                continue
            seen.add(name)
            if name in ("time", "duration"):
                out.append(_special_typedef(name))
            else:
                out += self.typedefs(self.message(name), seen)
        return out

    def typedef(self, definition: MsgDef) -> dict:
        """One rosapi_msgs/TypeDef: field names, types, array lengths (-1 one value, 0 a sequence), examples,
        constants (sorted by name, as inspect.getmembers lists them)."""
        constants = sorted(definition.constants, key=lambda c: c[1])
        return {
            "type": definition.name,
            "fieldnames": [f.name for f in definition.fields],
            "fieldtypes": [self._typedef_type(f) for f in definition.fields],
            "fieldarraylen": [-1 if f.array is None else f.array for f in definition.fields],
            "examples": [self._example(f) for f in definition.fields],
            "constnames": [c[1] for c in constants],
            "constvalues": [str(c[2]) for c in constants],
        }

    def _typedef_type(self, field: Field) -> str:
        return IDL.get(field.type, field.type) if self.ros_version == 2 else field.type

    def _example(self, field: Field) -> str:
        if field.array is not None:
            return "[]"
        if field.type not in PRIMITIVES:
            return "{}"
        return str(self._field_default(field))

    # ----- populate_instance -----
    def populate(self, definition: MsgDef, msg) -> dict:
        """Complete msg with the definition's defaults, or raise ConversionError as rosbridge would."""
        return Populate(self, definition.name).message(msg, definition, [])


class Populate:
    """One run of populate_instance: the root type for the error texts and the clock for headers."""

    def __init__(self, reg: Registry, root: str) -> None:
        self.reg, self.root, self.v2 = reg, root, reg.ros_version == 2

    def idl(self, field: Field, element: bool = False) -> str:
        """The field's type as the server names it in an error (ROS 2: the IDL name, e.g. double)."""
        base = IDL.get(field.type, field.type) if self.v2 else field.type
        if element or field.array is None:
            return base
        if self.v2:
            return f"{base}[{field.array}]" if field.array else f"sequence<{base}>"
        return f"{base}[{field.array or ''}]"

    def mismatch(self, stack: list[str], expected: str, value) -> ConversionError:
        found = type(value)
        if expected == self.root:
            return ConversionError(f"Expected a JSON object for type {self.root} but received a {found}")
        return ConversionError(
            f"{self.root} message requires a {expected} for field {'.'.join(stack)}, but got a {found}"
        )

    def message(self, msg, definition: MsgDef, stack: list[str]) -> dict:
        if not isinstance(msg, dict):
            raise self.mismatch(stack, definition.name, msg)
        out = self.reg.default(definition)
        if definition.name == HEADER:
            out["stamp"] = _now(self.v2)
        for name, value in msg.items():
            field = definition.field(name)
            if field is None:
                raise ConversionError(
                    f"Message type {self.root} does not have a field {'.'.join([*stack, name])}",
                    "NonexistentFieldException",
                )
            out[name] = self.value(value, field, [*stack, name])
        return out

    def value(self, value, field: Field, stack: list[str]):
        if field.binary:
            return self.binary(value, field)
        if field.array is not None:
            return self.array(value, field, stack)
        return self.scalar(value, field, stack)

    def scalar(self, value, field: Field, stack: list[str]):
        type_ = field.type
        if type_ in TIMES or type_ in ("time", "duration"):
            return self.time(value, field)
        if type_ in PRIMITIVES:
            return self.primitive(value, field, stack)
        sub = self.reg.message(type_)
        if sub is None:  # a type the simulator does not know: passed on as sent
            return value
        return self.message(value, sub, stack)

    def primitive(self, value, field: Field, stack: list[str]):
        type_, found = field.type, type(value)
        if self.v2 and isinstance(value, int) and type_ in FLOATS:  # bool too: float(True), as rosbridge
            value, found = float(value), float
        if found is bool:
            ok = type_ == "bool"
        elif found is int:
            ok = type_ in INTS or (not self.v2 and type_ in FLOATS)
        elif found is float:
            ok = type_ in FLOATS
        elif found is str:
            ok = type_ == "string"
        else:
            ok = False
        if not ok:
            raise self.mismatch(stack, self.idl(field), value)
        if self.v2 and type_ in INTS:
            lo, hi = INTS[type_]
            if not lo <= value < hi:
                kind = "an unsigned integer" if lo == 0 else "an integer"
                raise ConversionError(
                    f"The '{field.name}' field must be {kind} in [{lo}, {hi - 1}]", "AssertionError"
                )
        return float(value) if type_ in FLOATS else value

    def time(self, value, field: Field):
        """builtin_interfaces/Time (ROS 2) or time (ROS 1): "now", or sec(s)/nanosec/nsecs, unchecked."""
        ros1 = field.type in ("time", "duration")
        keys = ("secs", "nsecs") if ros1 else ("sec", "nanosec")
        if value == "now" and field.type in ("time", "builtin_interfaces/Time"):
            return _now(not ros1)
        out = dict.fromkeys(keys, 0)
        if not isinstance(value, dict):
            if ros1 or isinstance(value, str):
                return out
            raise ConversionError(f"argument of type '{type(value).__name__}' is not iterable", "TypeError")
        for key, names in zip(keys, (("sec", "secs"), ("nanosec", "nsecs")), strict=True):
            for name in names if not ros1 else (key,):
                if name in value:
                    out[key] = value[name]
                    break
        if not ros1:
            for key, (lo, hi) in zip(keys, ((-(2**31), 2**31), (0, 2**32)), strict=True):
                if not isinstance(out[key], int) or isinstance(out[key], bool):
                    raise ConversionError(f"The '{key}' field must be of type 'int'", "AssertionError")
                if not lo <= out[key] < hi:
                    kind = "an unsigned integer" if lo == 0 else "an integer"
                    raise ConversionError(
                        f"The '{key}' field must be {kind} in [{lo}, {hi - 1}]", "AssertionError"
                    )
        return out

    def binary(self, value, field: Field):
        """uint8[]/char[]: a base64 string or a list of bytes in; base64 out."""
        if isinstance(value, str):
            try:
                return base64.b64encode(base64.b64decode(value)).decode("ascii")
            except (binascii.Error, ValueError) as exc:
                if self.v2:
                    raise ConversionError(str(exc), "Error") from None
                return value
        if isinstance(value, list) and all(isinstance(b, int) and 0 <= b < 256 for b in value):
            return self.reg.wire_array(field, value)
        raise ConversionError(f"{self.root} message requires a uint8[] for field {field.name}")

    def array(self, value, field: Field, stack: list[str]):
        if type(value) not in (list, tuple):
            raise self.mismatch(stack, self.idl(field), value)
        if not value:
            return []
        numeric = field.type in INTS or field.type in FLOATS
        if self.v2 and numeric:
            return self.numeric_array(list(value), field)
        element = Field(field.name, field.type)
        return [self.value(v, element, stack) for v in value]

    def numeric_array(self, values: list, field: Field) -> list:
        """ROS 2 keeps numeric arrays in array.array (sequences) or numpy (fixed): no per-field texts."""
        floats = field.type in FLOATS
        for v in values:
            if isinstance(v, (int, float)) and (floats or not isinstance(v, float)):
                continue
            if field.array:
                raise ConversionError(f"could not convert string to float: {v!r}", "ValueError")
            what = "real number" if floats else "an integer"
            if floats:
                raise ConversionError(f"must be {what}, not {type(v).__name__}", "TypeError")
            raise ConversionError(
                f"'{type(v).__name__}' object cannot be interpreted as an integer", "TypeError"
            )
        if field.array and len(values) != field.array:
            raise ConversionError(
                f"could not broadcast input array from shape ({len(values)},) into shape ({field.array},)",
                "ValueError",
            )
        return [float(v) for v in values] if floats else [int(v) for v in values]


def _special_typedef(name: str) -> dict:
    """objectutils._get_special_typedef: ROS 1's time and duration."""
    return {
        "type": name,
        "fieldnames": ["secs", "nsecs"],
        "fieldtypes": ["int32", "int32"],
        "fieldarraylen": [-1, -1],
        "examples": ["0", "0"],
        "constnames": [],
        "constvalues": [],
    }


def _parts(text: str, count: int) -> list[str]:
    """The sections of a .srv or .action text (separated by `---` lines), padded to count."""
    parts = re.split(r"^---\s*$", text, flags=re.MULTILINE)
    return (parts + [""] * count)[:count]


def _action_text(pkg: str, action: str) -> list[str] | None:
    """Goal, result and feedback sections of pkg/action/<action>.action, None if there is none."""
    path = DEFS / pkg / "action" / f"{action}.action"
    return _parts(path.read_text(), 3) if path.is_file() else None


def _now(v2: bool) -> dict:
    t = time.time()
    sec, nsec = int(t), int((t % 1) * 1e9)
    return {"sec": sec, "nanosec": nsec} if v2 else {"secs": sec, "nsecs": nsec}


def _strip_comment(line: str) -> str:
    """The line without its comment ('#' outside quotes)."""
    quote = None
    for i, ch in enumerate(line):
        if ch in "'\"":
            quote = None if quote == ch else quote or ch
        elif ch == "#" and quote is None:
            return line[:i]
    return line


def _literal(type_: str, text: str, array: bool = False, constant: bool = False):
    """A default or constant value as written in a .msg file."""
    if type_ == "string" and not array:
        if constant:
            return text
        try:
            return ast.literal_eval(text)
        except (ValueError, SyntaxError):
            return text
    text = re.sub(r"\b(true|false)\b", lambda m: m[0].capitalize(), text, flags=re.IGNORECASE)
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text
    if type_ in FLOATS:
        return [float(v) for v in value] if array else float(value)
    if type_ == "bool":
        return [bool(v) for v in value] if array else bool(value)
    return list(value) if array else value
