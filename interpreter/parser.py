"""Turn one instruction in words into checked steps, with the paper's Table 9 type (no Django).

Pipeline, each pass linear in the length of the text:
tokens (regex) -> items (longest phrase match in the Grammar's table, typo correction: interpreter/tokens.py) ->
step drafts (slot filling, here, into interpreter/drafts.py's StepDraft) -> semantic checks (the paper's Figure 8: allValuesFrom as sets) -> the typed
Interpretation (fleetcore.interpretation).
"""

from __future__ import annotations

from fleetcore.actions import ACTIONS
from fleetcore.choice import ANY
from fleetcore.interpretation import Interpretation
from interpreter import forms
from interpreter.drafts import Dest, StepDraft
from interpreter.lexicon import Grammar, Place, phrase_key
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
from interpreter.tokens import Item, Lexer, fmt, merge_numbers, normalize, tokenize

MAX_WORDS = 300
_SLOTLESS = {"FILLER", "AND", "COMMA", "TIMES"}


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
        items = merge_numbers(items)
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
        elif step.amount is None and self._names_instruction(step) and float(item.value).is_integer():
            step.amount = item.value  # "cancel #12"
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

    def _names_instruction(self, step: StepDraft) -> bool:
        spec = ACTIONS.get(self._effective_action(step) or "")
        return bool(spec and spec.names_instruction)

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
    items = Lexer(grammar).run(tokens)
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
    return _interpretation(kind, steps, synonyms, why, question, problems)


def _interpretation(kind, steps, synonyms, why, question, problems) -> Interpretation:
    """The typed result, each step read back in words and the answer box's example from the problems."""
    return Interpretation(
        kind,
        tuple(steps),
        why,
        question,
        next((p.example for p in problems if p.example), None),
        dict(synonyms),
        tuple(forms.read_back(step) for step in steps),
        tuple(problems),
    )


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
    return _interpretation("V", [], {}, why, question, [problem])


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
    if spec is not None and spec.names_instruction and draft.amount is not None:
        step["instruction"] = int(draft.amount)
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
