"""A step as the parser fills it from the items (StepDraft, with its destination Dest), before it is checked:
what the parser writes and the problems (interpreter/problems.py) read. No Django."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Dest:
    kind: str  # place | concept | unknown | classword | missing_place
    name: str
    x: float | None = None
    y: float | None = None
    cls: str | None = None

    def as_dict(self) -> dict:
        return {"name": self.name, "x": self.x, "y": self.y}


@dataclass
class StepDraft:
    action: str | None = None
    unknown_verb: str | None = None
    robots: list[str] = field(default_factory=list)
    all: bool = False
    dest: Dest | None = None
    task_action: str | None = None
    count: int | None = None
    speed: str | None = None
    continuation: bool = False
    amount: float | None = None  # said with a unit (in that unit, after its factor)
    unit: str | None = None
    direction: tuple | None = None  # (unit, sign, amount meant when none is said)
    forever: bool = False
    negated: bool = False
    any: bool = False
    model: str | None = None
    exclude: list[str] = field(default_factory=list)
    loop: int | None = None  # the loop (patrol) this visit belongs to
    inherited_action: bool = False

    def empty(self) -> bool:
        return not (
            self.action
            or self.unknown_verb
            or self.robots
            or self.all
            or self.dest
            or self.task_action
            or self.amount is not None
            or self.direction
        )
