"""What keeps an instruction from running, in a person's words: each problem's question and an answer example that
fits it, "did you mean" for near-miss names, and the reason given with every interpretation (no Django).

The parser (interpreter/parser.py) finds the problems; this module words them.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import TYPE_CHECKING

from fleetcore.actions import ACTIONS
from interpreter.forms import MAX_STEPS, read_back

if TYPE_CHECKING:
    from interpreter.drafts import Dest, StepDraft

EXAMPLE_COORDS = "(2, -1)"


@dataclass
class Problem:
    level: str  # III (semantic) or V (not programmed)
    code: str
    word: str
    question: str
    example: str = ""  # an answer that fits the question, for the answer box


def _check_place(dest: Dest, spec, draft, grammar) -> Problem | None:
    if spec is None:
        return None
    if not spec.takes_destination:
        q = f"'{spec.name}' does not take a destination. Did you mean 'move ... to {dest.name}'?"
        example = f"move {_who(draft, grammar)} to {dest.name}"
        return Problem("III", "no_destination_expected", dest.name, q, example)
    if dest.cls not in spec.accepts:
        return _not_accepted(dest, spec, grammar, draft)
    return None


def _check_concept(dest: Dest, spec, draft, grammar) -> Problem | None:
    if spec is not None and (dest.cls not in spec.accepts or not spec.takes_destination):
        return _not_accepted(dest, spec, grammar, draft)
    q = f"Where is '{dest.name}' on the map? Answer '{dest.name} is a location at (x, y)'."
    return Problem("V", "unlocated", dest.name, q, f"{dest.name} is a location at (3, 4)")


def _not_accepted(dest: Dest, spec, grammar, draft=None) -> Problem:
    what = grammar.lexicon.class_descriptions.get(dest.cls or "", "not a place on the map")
    q = (
        f"'{dest.name}' is {what} — not a place on the map, so robots cannot {spec.name} there. "
        f"Choose a location ({_place_names(grammar)}) or coordinates like {EXAMPLE_COORDS}."
    )
    return Problem(
        "III",
        "invalid_destination",
        dest.name,
        q,
        f"{spec.name} {_who(draft, grammar)} to {_first_place(grammar)}",
    )


def _check_unknown(dest: Dest, spec, draft, grammar) -> Problem:
    w = dest.name
    near = _did_you_mean(w, [p.name for p in grammar.fleet.places])
    hint = f"Did you mean {near}? " if near else ""
    q = (
        f"I don't know '{w}'. {hint}If it is another word for a place, answer '{w} means {near or 'A'}'; if it "
        f"is a place on the map, answer '{w} is a location at (x, y)'; if robots cannot go there, answer "
        f"'{w} is not a place'."
    )
    return Problem("V", "unknown_destination", w, q, f"{w} means {near or _first_place(grammar)}")


def _check_missing_place(dest: Dest, spec, draft, grammar) -> Problem:
    q = f"There is no {dest.name} on the map. Known places: {_place_names(grammar)}."
    near = _did_you_mean(dest.name, [p.name for p in grammar.fleet.places])
    return Problem("V", "no_such_place", dest.name, q, f"{dest.name} means {near or _first_place(grammar)}")


def _check_classword(dest: Dest, spec, draft, grammar) -> Problem:
    q = f"Which {dest.name}? Known places: {_place_names(grammar)}."
    example = f"{draft.action or 'move'} {_who(draft, grammar)} to {_first_place(grammar, dest.cls)}"
    return Problem("III", "which_place", dest.name, q, example)


DEST_CHECKS = {
    "place": _check_place,
    "concept": _check_concept,
    "unknown": _check_unknown,
    "missing_place": _check_missing_place,
    "classword": _check_classword,
}


def missing_destination(draft: StepDraft, spec, grammar) -> Problem:
    who = ", ".join(draft.robots) if draft.robots else "the robots"
    q = (
        f"Where should {who} {spec.name.replace('_', ' ')}? Name a location ({_place_names(grammar)}) "
        f"or coordinates like {EXAMPLE_COORDS}."
    )
    example = f"{spec.name.replace('_', ' ')} {_who(draft, grammar)} to {_first_place(grammar)}"
    return Problem("III", "missing_destination", spec.name, q, example)


_AMOUNT_WORDS = {  # unit -> (question, example), for an action said without its amount
    "m": ("How far should {who} move?", "move {who} 1 meter forward"),
    "deg": ("By how many degrees should {who} turn?", "turn {who} left by 90 degrees"),
    "s": ("How long should {who} wait?", "wait 5 seconds"),
}


def missing_amount(draft: StepDraft, unit: str, grammar) -> Problem:
    who = ", ".join(draft.robots) if draft.robots else "the robot"
    question = _AMOUNT_WORDS[unit][0].format(who=who)
    example = _AMOUNT_WORDS[unit][1].format(who=_who(draft, grammar))
    return Problem(
        "III", "missing_amount", draft.action or "", f"{question} For example '{example}'.", example
    )


def known_verbs(grammar) -> str:
    """The actions a person starts an instruction with, for "I know: ...": not the questions (asked as "where
    is ...", "what is ... doing") nor the measured forms (move_by, turn_by: "move 2 meters", "turn left")."""

    def typed(name: str) -> bool:
        action = ACTIONS.get(name)
        return "_" not in name and (action is None or action.category != "query")

    return ", ".join(sorted(filter(typed, grammar.lexicon.actions)))


def unknown_verb(word: str, grammar) -> Problem:
    known = known_verbs(grammar)
    near = _did_you_mean(
        word, [r.name for r in grammar.fleet.robots] + [p.name for p in grammar.fleet.places]
    )
    if near:
        q = f"I don't know '{word}'. Did you mean {near}? If '{word}' is an action, answer e.g. '{word} means move'."
    else:
        q = f"I don't know the action '{word}'. Which action do you mean? Answer e.g. '{word} means move' (I know: {known})."
    return Problem("V", "unknown_action", word, q, f"{word} means move")


def no_action(draft: StepDraft | None, grammar) -> Problem:
    known = known_verbs(grammar)
    example = f"move {example_robot(grammar)} to {_first_place(grammar)}"
    q = f"What should the robots do? Start with an action, e.g. '{example}' (I know: {known})."
    return Problem("V", "no_action", "", q, example)


def stray_word(word: str, grammar=None) -> Problem:
    names = [r.name for r in grammar.fleet.robots] + [p.name for p in grammar.fleet.places] if grammar else []
    near = _did_you_mean(word, names)
    if near:
        q = f"I don't know '{word}'. Did you mean {near}? Rephrase with it, or teach me: '{word} means {near}'."
        return Problem("V", "unknown_word", word, q, f"{word} means {near}")
    q = f"I don't know what '{word}' means here. Rephrase without it, or teach me: '{word} means <a word I know>'."
    return Problem("V", "unknown_word", word, q, f"{word} means move")


def _nothing_to_repeat(grammar) -> Problem:
    example = f"move {example_robot(grammar)} to A then B, repeat 3 times"
    q = f"Repeat what? Say the steps first, e.g. '{example}'."
    return Problem("III", "nothing_to_repeat", "repeat", q, example)


def _too_many_steps(grammar) -> Problem:
    q = f"That makes more than {MAX_STEPS} steps. Fewer rounds, or 'until stopped' and a stop when it is enough."
    return Problem(
        "III", "too_many_steps", "", q, f"patrol A and B with {example_robot(grammar)} until stopped"
    )


LOOP_PROBLEMS = {"nothing_to_repeat": _nothing_to_repeat, "too_many_steps": _too_many_steps}


def _did_you_mean(word: str, names: list[str]) -> str | None:
    """The one name a near-miss most likely meant ("huskyy" -> husky, "Roon 3" -> Room 3), or None."""
    folded = {name.casefold(): name for name in names}
    hits = difflib.get_close_matches(word.casefold(), list(folded), n=1, cutoff=0.75)
    return folded[hits[0]] if hits and hits[0] != word.casefold() else None


def _who(draft: StepDraft | None, grammar) -> str:
    return draft.robots[0] if draft is not None and draft.robots else example_robot(grammar)


def _first_place(grammar, cls: str | None = None) -> str:
    places = [p.name for p in grammar.fleet.places if cls is None or p.cls == cls] or ["A"]
    return places[0]


def reason_of(kind: str, steps: list[dict], synonyms, corrections, problems, not_done=()) -> str:
    parts = [f"Type {kind}."]
    if synonyms:
        parts.append(
            ", ".join(f"'{w}' is a synonym of '{c}'" for w, c in synonyms.items()) + " (owl:sameAs)."
        )
    if corrections:
        parts.append("Read " + ", ".join(f"'{t}' as '{w}'" for t, w in corrections.items()) + ".")
    if problems:
        parts.append(" ".join(dict.fromkeys(_PROBLEM_WORDS[p.code].format(w=p.word) for p in problems)))
    elif steps:
        parts.append("Understood: " + "; then ".join(read_back(s) for s in steps) + ".")
    if not_done and not problems:
        parts.append(("Nothing to do: " if not steps else "Not done, as you said: ") + "; ".join(
            f"not {what}" for what in not_done) + ".")  # fmt: skip
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
    "missing_amount": "'{w}' needs an amount.",
    "nothing_to_repeat": "there is nothing before the repeat.",
    "too_many_steps": "the loop makes too many steps.",
    "empty": "The instruction is empty.",
    "too_long": "The instruction is too long.",
}


def _place_names(grammar, limit: int = 12) -> str:
    names = [p.name for p in grammar.fleet.places]
    if not names:
        return "none registered yet"
    shown = ", ".join(names[:limit])
    return shown + (", ..." if len(names) > limit else "")


def example_robot(grammar) -> str:
    return grammar.fleet.robots[0].name if grammar.fleet.robots else "husky"
