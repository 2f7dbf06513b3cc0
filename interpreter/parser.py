"""Turn one instruction in words into checked steps, with the paper's Table 9 type (no Django).

Pipeline, each pass linear in the length of the text:
tokens (regex) -> items (longest phrase match in the Grammar's table, typo correction) ->
step drafts (slot filling) -> semantic checks (the paper's Figure 8: allValuesFrom as sets) -> Interpretation.
"""

from __future__ import annotations

import math
import re
import unicodedata
from dataclasses import dataclass, field

from fleetcore.actions import ACTIONS
from fleetcore.steps import ANY
from interpreter import forms
from interpreter.lexicon import Grammar, Meaning, Place, phrase_key
from interpreter.problems import (
    DEST_CHECKS,
    LOOP_PROBLEMS,
    Problem,
    example_robot,
    missing_amount,
    missing_destination,
    no_action,
    reason_of,
    stray_word,
    unknown_verb,
)

MAX_WORDS = 300
_INVISIBLE_RE = re.compile("[\u00ad\u180e\u200b-\u200f\u202a-\u202e\u2060-\u2064\ufeff]")
_NUM = r"[-+]?\d+(?:\.\d+)?"
_TOKEN_RE = re.compile(
    rf"""(?P<coord>[(\[]\s*(?P<cx>{_NUM})\s*[,;]?\s*(?P<cy>{_NUM})\s*[)\]])
    |(?P<xy>(?<![^\W\d_])x\s*[:=]?\s*(?P<xx>{_NUM})\s*,?\s*(?:and\s+)?y\s*[:=]?\s*(?P<yy>{_NUM}))
    |(?P<num>{_NUM})(?P<suffix>cm|mm|m|secs|sec|s|mins|min|deg|x|°)?(?!\w)
    |(?P<word>°|[^\W_]+(?:['’_-][^\W_]+)*)
    |(?P<stop>[;.!?]+)
    |(?P<comma>,)""",
    re.X | re.I,
)
_SLOTLESS = {"FILLER", "AND", "COMMA", "TIMES"}


@dataclass(slots=True)
class Item:
    kind: str
    value: object
    text: str
    synonym: str | None = None
    corrected_from: str | None = None


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


@dataclass
class Interpretation:
    """The result: steps plus the paper's instruction type and, when needed, a question."""

    type: str
    steps: list[dict]
    synonyms_used: dict[str, str]
    reason: str
    question: str | None = None
    corrections: dict[str, str] = field(default_factory=dict)
    problems: list[Problem] = field(default_factory=list)
    not_done: list[str] = field(default_factory=list)  # what the text said not to do

    @property
    def valid(self) -> bool:
        return self.type in {"I", "II"}

    def as_dict(self) -> dict:
        """Return the JSON shape of the interpreter's API."""
        return {
            "type": self.type,
            "valid": self.valid,
            "needs_user": not self.valid,
            "question": self.question,
            "steps": self.steps,
            "synonyms_used": self.synonyms_used,
            "reason": self.reason,
            "answer_example": next((p.example for p in self.problems if p.example), None),
        }


def normalize(text: str) -> str:
    """Fold compatibility characters, drop invisible ones and control characters."""
    text = unicodedata.normalize("NFKC", text)
    text = _INVISIBLE_RE.sub("", text)
    return "".join(ch if ch.isprintable() else " " for ch in text)


def tokenize(text: str) -> list[tuple[str, str, object]]:
    """Split text into (kind, lower-case text, value) tokens; kinds W N C S M."""
    tokens = []
    for m in _TOKEN_RE.finditer(text):
        group = "num" if m.group("num") is not None else m.lastgroup
        if group in {"coord", "xy"}:
            a, b = (m.group("cx"), m.group("cy")) if group == "coord" else (m.group("xx"), m.group("yy"))
            tokens.append(("C", m.group(), _coords(a, b)))
        elif group == "num":
            tokens.append(("N", m.group("num"), _number(m.group("num"))))
            if m.group("suffix"):
                tokens.append(("W", m.group("suffix").casefold(), m.group("suffix")))
        elif group == "word":
            tokens.append(("W", m.group().casefold(), m.group()))
        else:
            tokens.append(("S" if group == "stop" else "M", m.group(), None))
    return tokens


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _coords(a: str, b: str) -> tuple[float, float] | None:
    x, y = _number(a), _number(b)
    return None if x is None or y is None else (x, y)


def fmt(value: float) -> str:
    return f"{value:g}"


class _Lexer:
    """Match the longest known phrase at each position; resolve ambiguity from context."""

    def __init__(self, grammar: Grammar):
        self.grammar = grammar
        self.items: list[Item] = []
        self.prev = "START"
        self.last_word = ""
        self.seen_dest = False

    def run(self, tokens: list[tuple[str, str, object]]) -> list[Item]:
        texts = [t[1] if t[0] in "WN" else "\0" for t in tokens]
        i, n = 0, len(tokens)
        while i < n:
            kind, text, value = tokens[i]
            if kind in "CSM":
                self._emit_special(kind, text, value)
                i += 1
                continue
            i += self._match(texts, i, n, tokens)
        return self.items

    def _emit_special(self, kind: str, text: str, value) -> None:
        if kind == "C" and value is not None:
            self._emit(Item("COORD", value, text))
        elif kind == "C":
            self._emit(Item("UNKNOWN", None, text))
        else:
            self._emit(Item("THEN" if kind == "S" else "COMMA", text, text))

    def _match(self, texts, i, n, tokens) -> int:
        for length in range(min(self.grammar.max_len, n - i), 0, -1):
            meanings = self.grammar.table.get(tuple(texts[i : i + length]))
            if meanings:
                raw = tokens[i][2]
                meaning = self._resolve(meanings, length == 1 and isinstance(raw, str) and raw.isupper())
                if meaning is not None:
                    phrase = " ".join(texts[i : i + length])
                    self._emit(Item(meaning.kind, meaning.value, phrase, meaning.synonym))
                    return length
        kind, text, value = tokens[i]
        if kind == "N":
            self._emit(Item("NUMBER", value, text) if value is not None else Item("UNKNOWN", None, text))
            return 1
        meaning = self.grammar.correct(text)
        if meaning is None:
            self._emit_unknown(text)
        else:
            self._emit(Item(meaning.kind, meaning.value, text, meaning.synonym, corrected_from=text))
        return 1

    def _resolve(self, meanings: list[Meaning], letter: bool = False) -> Meaning | None:
        """letter: the word is one capital letter right after an action ("patrol A and B"): a place's name."""
        dest_ctx = (
            self.prev in {"PREP", "CLASSWORD"}
            or (self.prev in {"THEN", "AND", "COMMA"} and self.seen_dest)
            or (letter and self.prev == "ACTION")
        )
        if len(meanings) == 1:
            return meanings[0]
        by_kind = {}
        for m in meanings:
            by_kind.setdefault(m.kind, m)
        if "PLACE" in by_kind and len(by_kind["PLACE"].value.name) == 1 and not dest_ctx:
            del by_kind["PLACE"]
        if (self.prev in {"ALL", "ANY", "EXCEPT"} or self.last_word in {"a", "an"}) and "KIND" in by_kind:
            return by_kind["KIND"]
        order = _DEST_ORDER if dest_ctx else _ORDER
        for kind in order:
            if kind in by_kind:
                return by_kind[kind]
        return next(iter(by_kind.values()))

    def _emit_unknown(self, text: str) -> None:
        last = self.items[-1] if self.items else None
        if last is not None and last.kind == "UNKNOWN" and self.prev == "UNKNOWN":
            last.text = f"{last.text} {text}"
            return
        self._emit(Item("UNKNOWN", None, text))

    def _emit(self, item: Item) -> None:
        self.items.append(item)
        if item.kind in {"PLACE", "COORD", "CONCEPT", "CLASSWORD"} or (
            item.kind == "UNKNOWN" and self.prev == "PREP"
        ):
            self.seen_dest = True
        self.last_word = item.text
        if item.kind != "FILLER":
            self.prev = item.kind


_ORDER = (
    "ROBOT", "ACTION", "PLACE", "KIND", "CONCEPT", "SPEED", "PREP", "ALL", "THEN", "AND",
    "NUMBER", "TIMES", "UNIT", "DIRECTION", "EXCEPT", "ANY", "NOT", "FOREVER", "CLASSWORD", "FILLER",
)  # fmt: skip
_DEST_ORDER = ("PLACE", "CONCEPT", "CLASSWORD", "ROBOT", "ACTION", "KIND", "SPEED", *_ORDER[5:])


class _Builder:
    """Fill the slots of one step after another from the items."""

    def __init__(self, grammar: Grammar):
        self.grammar = grammar
        self.lexicon = grammar.lexicon
        self.drafts = [StepDraft()]
        self.prev = "START"
        self.joined = False
        self.synonyms: dict[str, str] = {}
        self.corrections: dict[str, str] = {}
        self.stray: list[str] = []
        self.kind_words: list[str] = []
        self.not_done: list[str] = []
        self.next_kind = ""
        self.last_word = ""
        self.pending: float | None = None  # a number waiting for its unit
        self.negate: str | None = None  # "do not" said: the next action is not to be done
        self.excepting = False  # "except" said: the robots that follow are left out

    @property
    def cur(self) -> StepDraft:
        return self.drafts[-1]

    def new_step(self) -> StepDraft:
        if not self.cur.empty():
            self.drafts.append(StepDraft(continuation=True))
        return self.cur

    def run(self, items: list[Item]) -> list[StepDraft]:
        items = _merge_numbers(items)
        for index, item in enumerate(items):
            if item.corrected_from:
                self.corrections[item.corrected_from] = item.synonym or _canonical_text(item)
            if item.synonym:
                self.synonyms[item.synonym] = str(item.value)
            self.next_kind = next((i.kind for i in items[index + 1 :] if i.kind != "FILLER"), "")
            self._guard(item)
            getattr(self, f"on_{item.kind.lower()}")(item)
            if item.kind in {"AND", "COMMA"}:
                self.joined = True
            elif item.kind not in _SLOTLESS:
                self.joined = False
            if item.kind != "FILLER":
                self.prev = item.kind
            self.last_word = item.text
        if self.negate:
            self.stray.append(self.negate)
        return [d for d in self.drafts if not d.empty()]

    def _guard(self, item: Item) -> None:
        """A "not" applies to the next action only, "except" to the robots right after it; anything else
        after a "not" is asked about rather than ignored (never "go to A not B" -> both)."""
        if self.excepting and item.kind not in {"ROBOT", "KIND", "AND", "COMMA", "EXCEPT", "FILLER"}:
            self.excepting = False
        if self.negate and item.kind not in {"ACTION", "NOT", "FILLER", "SPEED", "AND"}:
            self.stray.append(self.negate)
            self.negate = None

    def on_action(self, item: Item) -> None:
        step, spec = self.cur, self.lexicon.actions[item.value]
        if self.negate:
            self.negate = None
            if step.action and spec.category == "task" and step.task_action is None:
                self.not_done.append(item.text)  # "move to A and do not clean": no clean
                return
            step = self.new_step() if step.action or step.unknown_verb else step
            step.action, step.negated = item.value, True
            return
        if step.action is None and step.unknown_verb is None and not (step.dest and self.joined):
            step.action = item.value
        elif spec.category == "task" and step.task_action is None and self._category(step) != "task":
            step.task_action = item.value
        else:
            self.new_step().action = item.value

    def on_not(self, item: Item) -> None:
        self.negate = item.text

    def on_except(self, item: Item) -> None:
        self.excepting = True

    def on_any(self, item: Item) -> None:
        self.cur.any = True

    def on_forever(self, item: Item) -> None:
        self.cur.forever = True

    def on_direction(self, item: Item) -> None:
        step = self.cur
        if step.direction is not None:
            step = self.new_step()
        step.direction = item.value

    def on_unit(self, item: Item) -> None:
        unit, factor = item.value
        value = self.pending if self.pending is not None else 1.0 if self.last_word in {"a", "an"} else None
        self.pending = None
        if value is None:
            self.stray.append(item.text)
            return
        step = self.cur
        if step.amount is not None:
            step = self.new_step()
        step.amount, step.unit = value * factor, unit

    def _category(self, step: StepDraft) -> str | None:
        spec = self.lexicon.actions.get(step.action or "")
        return spec.category if spec else None

    def on_robot(self, item: Item) -> None:
        if self.excepting:
            self.cur.exclude.append(item.value)
            return
        self._add_robots([item.value])

    def on_kind(self, item: Item) -> None:
        word, names, _plural = item.value
        self.kind_words.append(word)
        if self.excepting:
            self.cur.exclude.extend(n for n in names if n not in self.cur.exclude)
            return
        if self.cur.any or self.last_word in {"a", "an", "any"}:
            self.cur.any, self.cur.model = True, word  # "a turtlebot": the best one of that kind
            return
        self.cur.all = False
        self._add_robots(list(names))

    def _add_robots(self, names: list[str]) -> None:
        step = self.cur
        if step.action and (step.dest or step.task_action) and self.joined:
            step = self.new_step()
        step.robots.extend(n for n in names if n not in step.robots)

    def on_all(self, item: Item) -> None:
        self.cur.all = True

    def on_place(self, item: Item) -> None:
        place: Place = item.value
        self._set_dest(Dest("place", place.name, float(place.x), float(place.y), place.cls))

    def on_coord(self, item: Item) -> None:
        x, y = item.value
        self._set_dest(Dest("place", f"({fmt(x)}, {fmt(y)})", x, y, "Point"))

    def on_concept(self, item: Item) -> None:
        self._set_dest(Dest("concept", item.value, cls=self.lexicon.concepts.get(item.value)))

    def on_classword(self, item: Item) -> None:
        if self.cur.dest is None:
            self.cur.dest = Dest("classword", item.text, cls=item.value)

    def _set_dest(self, dest: Dest) -> None:
        step = self.cur
        if step.dest is not None and step.dest.kind != "classword":
            step = self.new_step()
        step.dest = dest

    def on_number(self, item: Item) -> None:
        step = self.cur
        if self.next_kind == "UNIT":
            self.pending = item.value
        elif self.prev == "UNKNOWN" and step.dest is not None and step.dest.kind == "unknown":
            step.dest.name = f"{step.dest.name} {item.text}"  # "Roon 3": one name, to ask about as one
        elif self.prev == "CLASSWORD" and step.dest is not None and step.dest.kind == "classword":
            step.dest = self._numbered_place(step.dest.cls, item.value)
        elif step.amount is None and self._unit_of(step) in {"s", "deg"} and item.value > 0:
            step.amount, step.unit = float(item.value), self._unit_of(step)  # "wait 5", "turn by 45"
        elif (
            step.count is None and self._countable(step) and float(item.value).is_integer() and item.value > 0
        ):
            step.count = int(item.value)
        else:
            self.stray.append(item.text)

    def _numbered_place(self, cls: str, number: float) -> Dest:
        """ "room three" -> the place "Room 3" when the map has it."""
        name = f"{cls} {fmt(number)}"
        for meaning in self.grammar.table.get(phrase_key(name), ()):
            if meaning.kind == "PLACE":
                place = meaning.value
                return Dest("place", place.name, float(place.x), float(place.y), place.cls)
        return Dest("missing_place", name, cls=cls)

    def _unit_of(self, step: StepDraft) -> str | None:
        spec = ACTIONS.get(self._effective_action(step) or "")
        return spec.unit if spec else None

    def _effective_action(self, step: StepDraft) -> str | None:
        """The step's action, or for a continuation ("patrol A and B twice") the one it will inherit."""
        if step.action or not step.continuation:
            return step.action
        return next((d.action for d in reversed(self.drafts[:-1]) if d.action), None)

    def _countable(self, step: StepDraft) -> bool:
        names = (step.task_action, self._effective_action(step))
        return any(self.lexicon.actions[n].countable for n in names if n in self.lexicon.actions)

    def on_unknown(self, item: Item) -> None:
        step = self.cur
        if self.prev in {"PREP", "CLASSWORD"} and (step.dest is None or step.dest.kind == "classword"):
            step.dest = Dest("unknown", item.text)
        elif step.action is None and step.unknown_verb is None and self.prev != "PREP":
            step.unknown_verb = item.text
        else:
            self.stray.append(item.text)

    def on_speed(self, item: Item) -> None:
        self.cur.speed = item.value

    def on_then(self, item: Item) -> None:
        self.new_step()

    def on_prep(self, item: Item) -> None:
        """Prepositions only mark that a destination follows."""

    on_and = on_comma = on_filler = on_times = on_prep


def _merge_numbers(items: list[Item]) -> list[Item]:
    """Number words said in parts become one number: "forty five" 45, "one hundred eighty" 180."""
    out: list[Item] = []
    for item in items:
        last = out[-1] if out else None
        if (
            item.kind == "NUMBER"
            and last is not None
            and last.kind == "NUMBER"
            and item.text.isalpha()
            and last.text.replace(" ", "").isalpha()
            and _joins(float(last.value), float(item.value))
        ):
            value = last.value * item.value if item.value == 100 else last.value + item.value
            out[-1] = Item("NUMBER", value, f"{last.text} {item.text}")
            continue
        out.append(item)
    return out


def _joins(first: float, second: float) -> bool:
    if second == 100:
        return 1 <= first < 10
    if first >= 100 and first % 100 == 0:
        return 1 <= second < 100
    return first >= 20 and first % 10 == 0 and 1 <= second < 10


def _canonical_text(item: Item) -> str:
    value = item.value
    if isinstance(value, Place):
        return value.name
    if isinstance(value, tuple):
        return str(value[0])
    return str(value)


def interpret(text: str, grammar: Grammar) -> Interpretation:
    """Interpret one instruction against a grammar (ontology snapshot + fleet)."""
    tokens = tokenize(normalize(text or ""))
    if not tokens:
        return check([], grammar, {}, {}, [], empty=True)
    if len(tokens) > MAX_WORDS:
        return check([], grammar, {}, {}, [], too_long=len(tokens))
    items = _Lexer(grammar).run(tokens)
    builder = _Builder(grammar)
    drafts = builder.run(items)
    return check(
        drafts, grammar, builder.synonyms, builder.corrections, builder.stray, not_done=builder.not_done
    )


# --- semantic checks (the paper's Figure 8) and the answer ------------------------------------------


def check(
    drafts, grammar, synonyms, corrections, stray, empty=False, too_long=0, not_done=()
) -> Interpretation:
    """Resolve inherited slots and the forms (amounts, loops, subjects), check every step against the ontology,
    and type the instruction."""
    if empty or too_long:
        return _refusal(grammar, too_long)
    problems: list[Problem] = []
    previous = None
    for draft in drafts:
        _inherit(draft, previous)
        previous = draft
    not_done = [*not_done, *(_describe_draft(d) for d in drafts if d.negated)]
    measured = []
    for draft in (d for d in drafts if not d.negated):
        parts, stray_amount = forms.measure(draft)
        measured += parts
        if stray_amount:
            stray.append(stray_amount)
    loops = forms.mark_loops(measured)
    steps = []
    for draft in measured:
        problems.extend(_check_step(draft, grammar))
        steps.append(_step_dict(draft, grammar))
    steps, why = forms.expand(measured, steps, loops, forms.MAX_STEPS)
    if why:
        problems.append(LOOP_PROBLEMS[why](grammar))
    problems.extend(stray_word(word, grammar) for word in stray)
    if not steps and not not_done:
        problems.append(no_action(None, grammar))
    kind = _type_of(problems, synonyms)
    question = " ".join(dict.fromkeys(p.question for p in problems[:3])) or None
    why = reason_of(kind, steps, synonyms, corrections, problems, not_done)
    return Interpretation(kind, steps, dict(synonyms), why, question, dict(corrections), problems, not_done)


def _describe_draft(draft: StepDraft) -> str:
    who = ", ".join(draft.robots) if draft.robots else "the robots"
    return f"{(draft.action or '').replace('_', ' ')} {who}".strip()


def _refusal(grammar, too_long: int) -> Interpretation:
    if too_long:
        why = f"The instruction is too long ({too_long} words; at most {MAX_WORDS})."
        question = "Please split it into shorter instructions, e.g. 'move husky to D then E'."
    else:
        why = "The instruction is empty."
        question = f"What should the robots do? For example 'move {example_robot(grammar)} to A'."
    problem = Problem("V", "empty" if not too_long else "too_long", "", question)
    return Interpretation("V", [], {}, why, question, {}, [problem])


def _inherit(draft: StepDraft, previous: StepDraft | None) -> None:
    if not (draft.continuation and previous):
        return
    if draft.action is None and draft.unknown_verb is None:
        draft.action = previous.action
        draft.unknown_verb = previous.unknown_verb
        draft.inherited_action = True
        draft.negated = draft.negated or previous.negated
    if not draft.robots and not draft.all and not draft.any and not draft.exclude:
        draft.robots, draft.all = list(previous.robots), previous.all
        draft.any, draft.model, draft.exclude = previous.any, previous.model, list(previous.exclude)
    if draft.speed is None:
        draft.speed = previous.speed


def _task(draft: StepDraft, grammar) -> str | None:
    actions = grammar.lexicon.actions
    name = draft.task_action
    if name is None and draft.action in actions and actions[draft.action].category == "task":
        name = draft.action
    if name is None:
        return None
    if actions[name].countable:
        return f"{name}({draft.count or 1})"
    return name


def _step_dict(draft: StepDraft, grammar) -> dict:
    spec = ACTIONS.get(draft.action)
    step = {
        "action": draft.action,
        "robots": forms.robots_of(draft, spec.unnamed if spec else ANY),
        "destination": draft.dest.as_dict() if draft.dest else None,
        "task": _task(draft, grammar),
        "speed": draft.speed,
    }
    if spec is not None and spec.unit in forms.MEASURED_UNITS and draft.amount is not None:
        step["amount"] = round(draft.amount, 3)
    return step


def _check_step(draft: StepDraft, grammar) -> list[Problem]:
    """Return what keeps this step from running: unknown words first, then semantic issues."""
    problems = []
    if draft.unknown_verb:
        problems.append(unknown_verb(draft.unknown_verb, grammar))
    elif draft.action is None:
        problems.append(no_action(draft, grammar))
    dest, spec = draft.dest, grammar.lexicon.actions.get(draft.action or "")
    if dest is not None and dest.kind in DEST_CHECKS:
        problem = DEST_CHECKS[dest.kind](dest, spec, draft, grammar)
        if problem:
            problems.append(problem)
    elif dest is None and spec is not None and spec.requires_destination:
        problems.append(missing_destination(draft, spec, grammar))
    unit = getattr(ACTIONS.get(draft.action or ""), "unit", None)
    if unit in forms.MEASURED_UNITS and draft.amount is None:
        problems.append(missing_amount(draft, unit, grammar))
    return problems


def _type_of(problems: list[Problem], synonyms: dict) -> str:
    levels = {p.level for p in problems}
    if "V" in levels:
        return "V"
    if "III" in levels:
        return "IV" if synonyms else "III"
    return "II" if synonyms else "I"
