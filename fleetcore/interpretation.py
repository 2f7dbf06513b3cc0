"""One instruction as understood: its type, its steps, who each step is for, and what to ask (no Django).

The parser produces it; `submit`, dispatch, the questions' answers, the API, the scheduler and make-way read it.
It is a dict only at the edges: `to_dict` for what is stored (`Instruction.parse`) and sent to browsers, and
`from_dict` for what comes back (a stored parse, an API caller's, make-way's); `wire_form` says the keys and their
types once, and the API's schema is generated from it (portal/interpretation_schema.py). The steps stay in the step
contract's wire form until `checked` (a type III-V instruction's steps may have no action or no position, so
they cannot all be `fleetcore.steps.Step`s); who each step is for is read through `choices` (one
`RobotChoice`), and "is it a stop", "is it a question", "which robots does a stop name" are decided here once.
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Literal, get_args, get_type_hints

from fleetcore import steps as step_contract
from fleetcore.actions import ACTIONS
from fleetcore.choice import ALL, ChoiceError, RobotChoice

# The paper's Table 9: I, II understood (II: through synonyms); III-V ask.
Type = Literal["I", "II", "III", "IV", "V"]
TYPES = get_args(Type)
EVERY = ALL  # what a stop naming no robot (or every robot) stops


def _says(doc: str, wire: bool = True) -> dict:
    """A field's metadata: what it says on the wire (the API schema's description), or that it stays off it."""
    return {"doc": doc, "wire": wire}


@dataclass(frozen=True)
class Interpretation:
    """The paper's type, the steps (wire form), why, and for types III-V the question and an answer's example."""

    type: Type = field(
        metadata=_says("I, II: understood (II: through synonyms); III-V: a question to answer")
    )
    steps: tuple[step_contract.StepWire, ...] = field(
        default=(), metadata=_says("the steps, in the step contract's wire form")
    )
    reason: str = field(default="", metadata=_says("why it was read so, or what is missing"))
    question: str | None = field(default=None, metadata=_says("types III-V: what the person is asked"))
    answer_example: str | None = field(default=None, metadata=_says("types III-V: an answer that would do"))
    synonyms_used: Mapping[str, str] = field(
        default_factory=dict, metadata=_says("each word read as another: {word: the word it means}")
    )
    read_back: tuple[str, ...] = field(  # (interpreter.forms.read_back): the console's lines
        default=(), metadata=_says("each step in words, in the order of steps")
    )
    problems: tuple = field(  # the parser's, for what a question asked
        default=(), compare=False, repr=False, metadata=_says("", wire=False)
    )
    WIRE_PROPERTIES = ("valid", "needs_user")  # decided here, sent with the fields (to_dict)

    # --- the one constructor for an instruction the portal writes itself -------------------------------

    @classmethod
    def direct(cls, steps: Iterable[dict], reason: str, read_back: Iterable[str] = ()) -> Interpretation:
        """Steps the portal wrote (click-to-move, a schedule's slot, make-way): type I, nothing to ask."""
        return cls("I", tuple(dict(step) for step in steps), reason, read_back=tuple(read_back))

    @classmethod
    def for_robots(
        cls,
        names: Iterable[str] | str,
        action: str,
        reason: str,
        destination: dict | None = None,
        task: str | None = None,
        speed: str | None = None,
        amount: float | None = None,
        read_back: Iterable[str] = (),
    ) -> Interpretation:
        """One step of `action` for the robots named (by the portal, never read from words), or for every
        robot (names EVERY): a stop through the API, a schedule's slot, make-way, click-to-move."""
        choice = RobotChoice(ALL) if names == EVERY else RobotChoice.named(*names)
        step = {"action": action, "robots": choice.to_wire(), "destination": destination, "task": task}
        step["speed"] = speed
        if amount is not None:
            step["amount"] = amount
        return cls.direct([step], reason, read_back)

    # --- the edges: stored JSON and the wire -------------------------------------------------------------

    @classmethod
    @functools.cache
    def wire_form(cls) -> Mapping[str, tuple[object, str]]:
        """Each key of `to_dict` with its type and what it says: the fields on the wire, then WIRE_PROPERTIES.
        The API's schema is generated from it (portal/interpretation_schema.py), so the two cannot differ."""
        hints = get_type_hints(cls)
        form = {f.name: (hints[f.name], f.metadata["doc"]) for f in fields(cls) if f.metadata["wire"]}
        for name in cls.WIRE_PROPERTIES:
            prop = getattr(cls, name)
            form[name] = (get_type_hints(prop.fget)["return"], prop.__doc__ or "")
        return MappingProxyType(form)

    def to_dict(self) -> dict:
        """The JSON shape of the interpreter's API, of `Instruction.parse` and of the console's parse."""
        return {name: _plain(getattr(self, name)) for name in self.wire_form()}

    @classmethod
    def from_dict(cls, data: Mapping) -> Interpretation:
        """Back from its JSON (a stored parse, a caller's); a bare {"steps": [...]} is type I. An unknown type,
        or an answer whose "valid" says otherwise than its type, is taken as asking (type V)."""
        if isinstance(data, Interpretation):
            return data
        kind = data.get("type") or "I"
        said_invalid = data.get("needs_user") or data.get("valid") is False
        if kind not in TYPES or (said_invalid and kind in ("I", "II")):
            kind = "V"
        raw = data.get("steps") or []
        return cls(
            kind,
            tuple(copy.deepcopy(step) for step in raw) if isinstance(raw, list | tuple) else (),
            str(data.get("reason") or ""),
            data.get("question"),
            data.get("answer_example"),
            dict(data.get("synonyms_used") or {}),
            tuple(data.get("read_back") or ()),
        )

    # --- what it is: each decided here once --------------------------------------------------------------

    @property
    def valid(self) -> bool:
        """Understood (types I, II): it can run."""
        return self.type in ("I", "II")

    @property
    def needs_user(self) -> bool:
        """Not understood (types III-V): it waits for the person's answer to the question."""
        return not self.valid

    @property
    def actions(self) -> list[str | None]:
        return [step.get("action") if isinstance(step, dict) else None for step in self.steps]

    @property
    def is_stop(self) -> bool:
        """A stop: some step stops robots (it never queues)."""
        return "stop" in self.actions

    @property
    def releases(self) -> bool:
        """ "release tiago": some step lets robots a stop holds move again."""
        return "release" in self.actions

    @property
    def cancels(self) -> bool:
        """ "cancel #12", "cancel husky's instruction": some step takes one instruction back (execution.tasklist)."""
        return "cancel" in self.actions

    @property
    def is_question(self) -> bool:
        """Every step asks something (answered from live state, nothing queued)."""
        kinds = [getattr(ACTIONS.get(action or ""), "category", "") for action in self.actions]
        return bool(kinds) and all(kind == "query" for kind in kinds)

    @property
    def choices(self) -> tuple[RobotChoice | None, ...]:
        """Who each step is for; None for a step whose robots are in no form a step takes."""
        return tuple(_choice(step) for step in self.steps)

    def checked(self) -> list[step_contract.Step]:
        """Every step against the step contract; StepError (a sentence for a person) for the first that fails."""
        return step_contract.validate(list(self.steps))

    def named(self) -> set[str]:
        """The robots named by name in any step (a question's robots wait for the answer)."""
        return {name for choice in self.choices if choice and choice.mode == "names" for name in choice.names}

    def stop_names(self, fleet: Callable[[], Iterable[tuple[str, str, str]]]) -> set[str] | str:
        """The robots a stop (or release) names, or EVERY ("stop", "stop all", "halt everything"); "stop every
        robot except husky" names the others: fleet() gives (name, model, drive) of every robot, read only then."""
        names: set[str] = set()
        for choice in self.choices:
            if choice is not None and choice.filtered:
                names |= {name for name, model, drive in fleet() if choice.means(name, model, drive)}
            elif choice is None or choice.mode != "names":
                return EVERY
            else:
                names |= set(choice.names)
        return names


def _plain(value):
    """A field as JSON takes it: tuples as lists, mappings as dicts, the steps copied (never shared)."""
    if isinstance(value, tuple):
        return copy.deepcopy(list(value))
    return dict(value) if isinstance(value, Mapping) else value


def _choice(step) -> RobotChoice | None:
    try:
        return RobotChoice.of(step.get("robots")) if isinstance(step, dict) else None
    except ChoiceError:
        return None
