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
from fleetcore.steps import ALL, ANY
from interpreter.lexicon import Grammar, Meaning, Place

MAX_WORDS = 300
_INVISIBLE_RE = re.compile("[\u00ad\u180e\u200b-\u200f\u202a-\u202e\u2060-\u2064\ufeff]")
_NUM = r"[-+]?\d+(?:\.\d+)?"
_TOKEN_RE = re.compile(
    rf"""(?P<coord>[(\[]\s*(?P<cx>{_NUM})\s*[,;]?\s*(?P<cy>{_NUM})\s*[)\]])
    |(?P<xy>(?<![^\W\d_])x\s*[:=]?\s*(?P<xx>{_NUM})\s*,?\s*(?:and\s+)?y\s*[:=]?\s*(?P<yy>{_NUM}))
    |(?P<num>{_NUM})(?!\w)
    |(?P<word>[^\W_]+(?:['’_-][^\W_]+)*)
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

    def empty(self) -> bool:
        return not (
            self.action or self.unknown_verb or self.robots or self.all or self.dest or self.task_action
        )


@dataclass
class Problem:
    level: str  # III (semantic) or V (not programmed)
    code: str
    word: str
    question: str


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
        group = m.lastgroup
        if group in {"coord", "xy"}:
            a, b = (m.group("cx"), m.group("cy")) if group == "coord" else (m.group("xx"), m.group("yy"))
            tokens.append(("C", m.group(), _coords(a, b)))
        elif group == "num":
            tokens.append(("N", m.group(), _number(m.group())))
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
                meaning = self._resolve(meanings)
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

    def _resolve(self, meanings: list[Meaning]) -> Meaning | None:
        dest_ctx = self.prev in {"PREP", "CLASSWORD"} or (
            self.prev in {"THEN", "AND", "COMMA"} and self.seen_dest
        )
        if len(meanings) == 1:
            return meanings[0]
        by_kind = {}
        for m in meanings:
            by_kind.setdefault(m.kind, m)
        if "PLACE" in by_kind and len(by_kind["PLACE"].value.name) == 1 and not dest_ctx:
            del by_kind["PLACE"]
        if self.prev == "ALL" and "KIND" in by_kind:
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
        if item.kind != "FILLER":
            self.prev = item.kind


_ORDER = (
    "ROBOT", "ACTION", "PLACE", "KIND", "CONCEPT", "SPEED", "PREP", "ALL", "THEN", "AND",
    "NUMBER", "TIMES", "CLASSWORD", "FILLER",
)  # fmt: skip
_DEST_ORDER = ("PLACE", "CONCEPT", "CLASSWORD", "ROBOT", "ACTION", "KIND", "SPEED", *_ORDER[5:])


class _Builder:
    """Fill the slots of one step after another from the items."""

    def __init__(self, grammar: Grammar):
        self.lexicon = grammar.lexicon
        self.drafts = [StepDraft()]
        self.prev = "START"
        self.joined = False
        self.synonyms: dict[str, str] = {}
        self.corrections: dict[str, str] = {}
        self.stray: list[str] = []
        self.kind_words: list[str] = []

    @property
    def cur(self) -> StepDraft:
        return self.drafts[-1]

    def new_step(self) -> StepDraft:
        if not self.cur.empty():
            self.drafts.append(StepDraft(continuation=True))
        return self.cur

    def run(self, items: list[Item]) -> list[StepDraft]:
        for item in items:
            if item.corrected_from:
                self.corrections[item.corrected_from] = item.synonym or _canonical_text(item)
            if item.synonym:
                self.synonyms[item.synonym] = str(item.value)
            getattr(self, f"on_{item.kind.lower()}")(item)
            if item.kind in {"AND", "COMMA"}:
                self.joined = True
            elif item.kind not in _SLOTLESS:
                self.joined = False
            if item.kind != "FILLER":
                self.prev = item.kind
        return [d for d in self.drafts if not d.empty()]

    def on_action(self, item: Item) -> None:
        step, spec = self.cur, self.lexicon.actions[item.value]
        if step.action is None and step.unknown_verb is None:
            step.action = item.value
        elif spec.category == "task" and step.task_action is None and self._category(step) != "task":
            step.task_action = item.value
        else:
            self.new_step().action = item.value

    def _category(self, step: StepDraft) -> str | None:
        spec = self.lexicon.actions.get(step.action or "")
        return spec.category if spec else None

    def on_robot(self, item: Item) -> None:
        self._add_robots([item.value])

    def on_kind(self, item: Item) -> None:
        word, names, _plural = item.value
        self.kind_words.append(word)
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
        if self.prev == "CLASSWORD" and step.dest is not None and step.dest.kind == "classword":
            step.dest = Dest("missing_place", f"{step.dest.cls} {fmt(item.value)}", cls=step.dest.cls)
        elif (
            step.count is None and self._countable(step) and float(item.value).is_integer() and item.value > 0
        ):
            step.count = int(item.value)
        else:
            self.stray.append(item.text)

    def _countable(self, step: StepDraft) -> bool:
        names = (step.task_action, step.action)
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
    return check(drafts, grammar, builder.synonyms, builder.corrections, builder.stray)


# --- semantic checks (the paper's Figure 8) and the answer ------------------------------------------

_EXAMPLE_COORDS = "(2, -1)"


def check(drafts, grammar, synonyms, corrections, stray, empty=False, too_long=0) -> Interpretation:
    """Resolve inherited slots, check every step against the ontology, and type the instruction."""
    if empty or too_long:
        return _refusal(grammar, too_long)
    steps, problems = [], []
    previous = None
    for draft in drafts:
        _inherit(draft, previous)
        problems.extend(_check_step(draft, grammar))
        steps.append(_step_dict(draft, grammar))
        previous = draft
    problems.extend(_stray_problem(word) for word in stray)
    if not steps:
        problems.append(_no_action_problem(None, grammar))
    kind = _type_of(problems, synonyms)
    question = " ".join(dict.fromkeys(p.question for p in problems[:3])) or None
    reason = _reason(kind, steps, synonyms, corrections, problems)
    return Interpretation(kind, steps, dict(synonyms), reason, question, dict(corrections), problems)


def _refusal(grammar, too_long: int) -> Interpretation:
    if too_long:
        why = f"The instruction is too long ({too_long} words; at most {MAX_WORDS})."
        question = "Please split it into shorter instructions, e.g. 'move husky to D then E'."
    else:
        why = "The instruction is empty."
        question = f"What should the robots do? For example 'move {_example_robot(grammar)} to A'."
    problem = Problem("V", "empty" if not too_long else "too_long", "", question)
    return Interpretation("V", [], {}, why, question, {}, [problem])


def _inherit(draft: StepDraft, previous: StepDraft | None) -> None:
    if not (draft.continuation and previous):
        return
    if draft.action is None and draft.unknown_verb is None:
        draft.action = previous.action
        draft.unknown_verb = previous.unknown_verb
    if not draft.robots and not draft.all:
        draft.robots, draft.all = list(previous.robots), previous.all
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
    robots = list(draft.robots) or (ALL if draft.all else spec.unnamed if spec else ANY)
    return {
        "action": draft.action,
        "robots": robots,
        "destination": draft.dest.as_dict() if draft.dest else None,
        "task": _task(draft, grammar),
        "speed": draft.speed,
    }


def _check_step(draft: StepDraft, grammar) -> list[Problem]:
    """Return what keeps this step from running: unknown words first, then semantic issues."""
    problems = []
    if draft.unknown_verb:
        problems.append(_unknown_verb_problem(draft.unknown_verb, grammar))
    elif draft.action is None:
        problems.append(_no_action_problem(draft, grammar))
    dest, spec = draft.dest, grammar.lexicon.actions.get(draft.action or "")
    if dest is not None and dest.kind in _DEST_CHECKS:
        problem = _DEST_CHECKS[dest.kind](dest, spec, draft, grammar)
        if problem:
            problems.append(problem)
    elif dest is None and spec is not None and spec.requires_destination:
        problems.append(_missing_dest_problem(draft, spec, grammar))
    return problems


def _check_place(dest: Dest, spec, draft, grammar) -> Problem | None:
    if spec is None:
        return None
    if not spec.takes_destination:
        q = f"'{spec.name}' does not take a destination. Did you mean 'move ... to {dest.name}'?"
        return Problem("III", "no_destination_expected", dest.name, q)
    if dest.cls not in spec.accepts:
        return _not_accepted(dest, spec, grammar)
    return None


def _check_concept(dest: Dest, spec, draft, grammar) -> Problem | None:
    if spec is not None and (dest.cls not in spec.accepts or not spec.takes_destination):
        return _not_accepted(dest, spec, grammar)
    q = f"Where is '{dest.name}' on the map? Answer '{dest.name} is a location at (x, y)'."
    return Problem("V", "unlocated", dest.name, q)


def _not_accepted(dest: Dest, spec, grammar) -> Problem:
    what = grammar.lexicon.class_descriptions.get(dest.cls or "", "not a place on the map")
    q = (
        f"'{dest.name}' is {what} — not a place on the map, so robots cannot {spec.name} there. "
        f"Choose a location ({_place_names(grammar)}) or coordinates like {_EXAMPLE_COORDS}."
    )
    return Problem("III", "invalid_destination", dest.name, q)


def _check_unknown(dest: Dest, spec, draft, grammar) -> Problem:
    w = dest.name
    q = (
        f"I don't know '{w}'. If it is another word for a place, answer '{w} means A'; if it is a place "
        f"on the map, answer '{w} is a location at (x, y)'; if robots cannot go there, answer "
        f"'{w} is not a place'."
    )
    return Problem("V", "unknown_destination", w, q)


def _check_missing_place(dest: Dest, spec, draft, grammar) -> Problem:
    q = f"There is no {dest.name} on the map. Known places: {_place_names(grammar)}."
    return Problem("V", "no_such_place", dest.name, q)


def _check_classword(dest: Dest, spec, draft, grammar) -> Problem:
    q = f"Which {dest.name}? Known places: {_place_names(grammar)}."
    return Problem("III", "which_place", dest.name, q)


_DEST_CHECKS = {
    "place": _check_place,
    "concept": _check_concept,
    "unknown": _check_unknown,
    "missing_place": _check_missing_place,
    "classword": _check_classword,
}


def _missing_dest_problem(draft: StepDraft, spec, grammar) -> Problem:
    who = ", ".join(draft.robots) if draft.robots else "the robots"
    q = (
        f"Where should {who} {spec.name}? Name a location ({_place_names(grammar)}) "
        f"or coordinates like {_EXAMPLE_COORDS}."
    )
    return Problem("III", "missing_destination", spec.name, q)


def _unknown_verb_problem(word: str, grammar) -> Problem:
    known = ", ".join(sorted(grammar.lexicon.actions))
    q = f"I don't know the action '{word}'. Which action do you mean? Answer e.g. '{word} means move' (I know: {known})."
    return Problem("V", "unknown_action", word, q)


def _no_action_problem(draft: StepDraft | None, grammar) -> Problem:
    known = ", ".join(sorted(grammar.lexicon.actions))
    q = f"What should the robots do? Start with an action, e.g. 'move {_example_robot(grammar)} to A' (I know: {known})."
    return Problem("V", "no_action", "", q)


def _stray_problem(word: str) -> Problem:
    q = f"I don't know what '{word}' means here. Rephrase without it, or teach me: '{word} means <a word I know>'."
    return Problem("V", "unknown_word", word, q)


def _type_of(problems: list[Problem], synonyms: dict) -> str:
    levels = {p.level for p in problems}
    if "V" in levels:
        return "V"
    if "III" in levels:
        return "IV" if synonyms else "III"
    return "II" if synonyms else "I"


def _reason(kind: str, steps: list[dict], synonyms, corrections, problems) -> str:
    parts = [f"Type {kind}."]
    if synonyms:
        parts.append(
            ", ".join(f"'{w}' is a synonym of '{c}'" for w, c in synonyms.items()) + " (owl:sameAs)."
        )
    if corrections:
        parts.append("Read " + ", ".join(f"'{t}' as '{w}'" for t, w in corrections.items()) + ".")
    if problems:
        parts.append(" ".join(dict.fromkeys(_PROBLEM_WORDS[p.code].format(w=p.word) for p in problems)))
    else:
        parts.append("Understood: " + "; then ".join(_describe(s) for s in steps) + ".")
    return " ".join(parts)


_PROBLEM_WORDS = {
    "unknown_action": "'{w}' is not an action I know.",
    "no_action": "No action was given.",
    "unknown_destination": "'{w}' is not a concept I know.",
    "unknown_word": "'{w}' is not a word I know here.",
    "invalid_destination": "'{w}' is a known concept but not a valid destination (owl:allValuesFrom).",
    "no_destination_expected": "the action does not take a destination ('{w}').",
    "missing_destination": "'{w}' needs a destination.",
    "which_place": "'{w}' names a kind of place, not one place.",
    "no_such_place": "there is no {w} on the map.",
    "unlocated": "'{w}' has no position on the map.",
    "empty": "The instruction is empty.",
    "too_long": "The instruction is too long.",
}


def _describe(step: dict) -> str:
    robots = step["robots"] if isinstance(step["robots"], str) else ", ".join(step["robots"])
    text = f"{step['action']} {robots}"
    if step["destination"]:
        text += f" to {step['destination']['name']}"
    if step["task"]:
        text += f" and {step['task']}"
    if step["speed"]:
        text += f" ({step['speed']})"
    return text


def _place_names(grammar, limit: int = 12) -> str:
    names = [p.name for p in grammar.fleet.places]
    if not names:
        return "none registered yet"
    shown = ", ".join(names[:limit])
    return shown + (", ..." if len(names) > limit else "")


def _example_robot(grammar) -> str:
    return grammar.fleet.robots[0].name if grammar.fleet.robots else "husky"
