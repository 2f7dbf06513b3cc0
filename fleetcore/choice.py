"""Which robots an instruction means, decided once (no Django).

A step names its robots in one of five forms: names, all, any (or none said), a kind ("all turtlebots",
"a legged robot") or an exclusion ("every robot except husky"). `RobotChoice` is that one type; on the wire
(JSON in the database, the API, the socket) it is a list of names, "all", "any", or a subject object
{"all"|"any": true, "model": word, "except": [names]}. `RobotChoice.means` says whether one robot of the fleet is
among them; `unnamed` whether the portal is to choose the robot (allocation). Dispatch, the questions' answers
and the stop's names all ask here, and only read the database themselves.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Annotated, Literal, TypedDict

NAMES, ALL, ANY = "names", "all", "any"  # exactly these; every free robot; the one best robot (allocation)

# The wire form, declared once (the API's schema is generated from it, portal/interpretation_schema.py): a list of
# names, "all", "any" (None: any), or the subject object for a kind or an exclusion ("except" is a keyword, hence
# the functional form).
SubjectWire = TypedDict(
    "SubjectWire",
    {
        "all": Annotated[bool, "true: every robot of the kind"],
        "any": Annotated[bool, "true: the one best robot of the kind (the portal chooses)"],
        "model": Annotated[str | None, 'a kind word: "turtlebot", "legged"'],
        "except": Annotated[list[str], "the robots left out, by name"],
    },
    total=False,
)
SubjectWire.__doc__ = """All or any robots of a kind ("model": a kind word), but those "except" names."""
RobotsWire = list[str] | Literal["all", "any"] | SubjectWire | None


class ChoiceError(ValueError):
    """Robots said in no form a step takes; the message says why, for a person."""


@dataclass(frozen=True)
class RobotChoice:
    """Who a step is for: names, all or any, of a kind (a kind word) and but some (exclude)."""

    mode: str  # NAMES, ALL or ANY
    names: tuple[str, ...] = ()  # mode NAMES: exactly these
    kind: str | None = None  # "turtlebot", "legged": only robots of that kind
    exclude: tuple[str, ...] = ()

    @classmethod
    def named(cls, *names: str) -> RobotChoice:
        return cls(NAMES, tuple(names))

    @classmethod
    def of(cls, value) -> RobotChoice:
        """The choice from its wire form (None or "" is any); ChoiceError for anything else."""
        if isinstance(value, RobotChoice):
            return value
        if value in (None, "", ANY):
            return cls(ANY)
        if value == ALL:
            return cls(ALL)
        if isinstance(value, dict):
            return cls._subject(value)
        if isinstance(value, list | tuple) and not value:
            raise ChoiceError("Say which robot should do it (a name, 'all robots' or 'any robot').")
        if isinstance(value, list | tuple) and all(isinstance(v, str) and v for v in value):
            return cls(NAMES, tuple(value))
        raise ChoiceError("robots is a list of robot names, 'all' or 'any'")

    @classmethod
    def _subject(cls, value: dict) -> RobotChoice:
        modes = [mode for mode in (ALL, ANY) if value.get(mode) is True]
        kind, exclude = value.get("model") or None, value.get("except") or []
        if (
            len(modes) != 1
            or set(value) - SubjectWire.__optional_keys__
            or not (kind is None or isinstance(kind, str))
            or not (isinstance(exclude, list) and all(isinstance(name, str) and name for name in exclude))
        ):
            raise ChoiceError(
                'robots as an object is {"all": true} or {"any": true}, with "model" and "except" if any'
            )
        return cls(modes[0], (), kind, tuple(exclude))

    def to_wire(self) -> RobotsWire:
        """Its JSON form: names as a list, "all", "any", or the subject object for a kind or an exclusion."""
        if self.mode == NAMES:
            return list(self.names)
        if not (self.kind or self.exclude):
            return self.mode
        out: dict = {self.mode: True}
        if self.kind:
            out["model"] = self.kind
        if self.exclude:
            out["except"] = list(self.exclude)
        return out

    @property
    def unnamed(self) -> bool:
        """The portal is to choose the robot: "any" or none said, or any one of a kind."""
        return self.mode == ANY

    @property
    def filtered(self) -> bool:
        """Chosen by kind or exclusion: who it means depends on the fleet's models."""
        return bool(self.kind or self.exclude)

    def means(self, name: str, model: str = "", drive: str = "") -> bool:
        """Whether the robot (its name, model and drive) is among those meant: one of the names given; for all
        or any, one of its kind (when one is said) and not excepted."""
        if self.mode == NAMES:
            return name in self.names
        if name in self.exclude:
            return False
        return not self.kind or self.kind.casefold() in kind_words(model, drive)

    def words(self) -> str:
        """Names; "every robot", "every turtlebot except husky"; "a robot the portal chooses"."""
        if self.mode == NAMES:
            return ", ".join(self.names)
        kind = self.kind or "robot"
        words = f"every {kind}" if self.mode == ALL else f"a {kind} the portal chooses"
        return words + (f" except {', '.join(self.exclude)}" if self.exclude else "")


def kind_words(model: str, drive: str) -> set[str]:
    """Words that name a robot kind: 'turtlebot3_burger' gives turtlebot3, turtlebot, burger."""
    words = set()
    model = model.casefold().strip()
    if model:
        words.add(model.replace("_", " "))
        for part in re.split(r"[_\-\s]+", model):
            if len(part) >= 3:
                words.add(part)
                stem = part.rstrip("0123456789")
                if len(stem) >= 3:
                    words.add(stem)
    if drive in {"wheeled", "legged"}:
        words.add(drive)
    return words


def unnamed(robots) -> bool:
    """The step (its robots in any form) leaves the robot to the portal."""
    return RobotChoice.of(robots).unnamed


def means(robots, name: str, model: str = "", drive: str = "") -> bool:
    """Whether the robot is among those a step's robots (in any form) mean."""
    return RobotChoice.of(robots).means(name, model, drive)
