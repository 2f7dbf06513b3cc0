"""The words the parser knows: ontology terms, the fleet's names and the grammar's words (fleetcore.grammar; no Django).

A `Grammar` is built once per (ontology version, fleet version) and then only read, so that
interpreting one instruction is a handful of dict look-ups per word.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from rapidfuzz import process
from rapidfuzz.distance import OSA

from fleetcore.choice import kind_words
from fleetcore.grammar import COUNT_WORDS, GRAMMAR, SPEED_PHRASES
from fleetcore.steps import DIRECTIONS, UNITS
from interpreter.terms import Terms, class_ancestry

WORD_RE = re.compile(
    r"[^\W_]+(?:['’_-][^\W_]+)*|\d+(?:\.\d+)?"
)  # a name may hold _ and - (turtlebot3_burger_2, robot-7)


def _words(text: str) -> frozenset[str]:
    return frozenset(text.split())


FILLERS = _words(
    """please pls plz kindly the a an robot robots bot bots can could would will you u should shall
    must i we want need like me us let lets let's ahead just now right away immediately straight directly
    ok okay hey hi hello thanks thank yourself yourselves itself themselves your their its my our of with
    there again also too both some bit little so up over location place waypoint point spot area
    position coordinates coordinate is are be get make sure try way"""
)
# Real English words one typo away from a term: never "correct" these, ask instead.
COMMON_WORDS = _words(
    """more mode love mole mope mote movie moved mover moves stop step shop stoop stomp atop slop spot spat
    shot slot spit snot spout sport soot clean clear clan cleat clans head heat heal hear held heed herd
    halt hall half salt hale walk wall talk well wale shift shirt shaft swift shit drive drove dive dries
    drier turn torn tern turf spin spun span skin spit spine room root rook roof rood moon moan mood moor
    hoof husk hunk dusky hussy tango advice proceeds precede travel gravel ravel navigate navigator mop map
    mob mom mad wash wish cash gash sweep sweet sleep steep tidy tiny tide tied pause cause spurt march
    match marsh mars marks park dock deck duck lock rock sock luck cock dork halt hang high stay star stir
    stare start store story scan slow flow blow glow show fast last cast past vast fist list mist"""
)


@dataclass(frozen=True)
class ActionSpec:
    """An action the parser can check destinations against (allValuesFrom as a set of classes)."""

    name: str
    category: str
    takes_destination: bool
    requires_destination: bool
    countable: bool
    accepts: frozenset[str]


@dataclass(frozen=True)
class Place:
    """A named location on the map, or coordinates."""

    name: str
    x: float
    y: float
    cls: str  # Room | Waypoint | Point | Location


@dataclass(frozen=True)
class RobotInfo:
    name: str
    model: str = ""
    drive: str = ""


@dataclass(frozen=True)
class Meaning:
    """What one phrase can mean: kind is ROBOT, KIND, ACTION, PLACE, CONCEPT, CLASSWORD, SPEED, ..."""

    kind: str
    value: object
    synonym: str | None = None  # the word as said when it is an owl:sameAs synonym


def phrase_key(text: str) -> tuple[str, ...]:
    """Split a term into the lower-case words the tokenizer would produce."""
    return tuple(w.casefold() for w in WORD_RE.findall(text))


def grammar_phrases(kind: str) -> set[tuple[str, ...]]:
    """The phrases of one grammar word kind ("ALL", "AND", "THEN", ...), as token tuples."""
    return {phrase_key(phrase) or (phrase,) for phrase in GRAMMAR[kind].split("|")}


def grammar_words() -> set[str]:
    """Every word of the little grammar (all kinds)."""
    return {word for kind in GRAMMAR for phrase in grammar_phrases(kind) for word in phrase}


def key_variants(text: str) -> set[tuple[str, ...]]:
    """Spellings of a name a person may type: 'Room 1', 'room1', 'robot 1', 'tb3 nav2'."""
    words = phrase_key(text.replace("_", " ")) or ()
    joined = "".join(words)
    out = {phrase_key(text), words}
    if joined:
        out.add((joined,))
        out.add(tuple(re.findall(r"[^\W\d_]+|\d+", joined)))
    return {k for k in out if k}


def plural_forms(word: str) -> set[str]:
    """Return the plural spellings of a kind word."""
    forms = {word + "s", word + "es"}
    if word.endswith("y") and len(word) > 2:
        forms.add(word[:-1] + "ies")
    return forms


class Lexicon:
    """A plain snapshot of the ontology: actions with their allowed destination classes, synonyms."""

    def __init__(self, terms: Terms, version: str = "0"):
        self.version = version
        chain = class_ancestry(terms.classes)
        on_map = {c.name for c in terms.classes if c.on_map}
        self.class_chain = chain
        self.class_descriptions = {c.name: c.description or c.name for c in terms.classes}
        self.map_classes = frozenset(on_map)
        self.actions = {a.name: self._spec(a, chain) for a in terms.actions}
        self.concepts = {c.name.casefold(): c.cls for c in terms.concepts}
        self.action_phrases: dict[tuple[str, ...], Meaning] = {}
        self.concept_phrases: dict[tuple[str, ...], Meaning] = {}
        for a in terms.actions:
            for word in {a.name, a.name.replace("_", " ")}:
                self.action_phrases[phrase_key(word)] = Meaning("ACTION", a.name)
        for c in terms.concepts:
            self.concept_phrases[phrase_key(c.name)] = Meaning("CONCEPT", c.name.casefold())
        for s in terms.synonyms:
            key = phrase_key(s.word)
            if s.action in self.actions and key not in self.action_phrases:
                self.action_phrases[key] = Meaning("ACTION", s.action, s.word.casefold())
            elif s.concept and s.concept.casefold() in self.concepts and key not in self.concept_phrases:
                self.concept_phrases[key] = Meaning("CONCEPT", s.concept.casefold(), s.word.casefold())

    @staticmethod
    def _spec(a, chain) -> ActionSpec:
        accepts = frozenset(name for name, anc in chain.items() if set(anc) & set(a.accepts))
        return ActionSpec(
            a.name, a.category, a.takes_destination, a.requires_destination, a.countable, accepts
        )


class Fleet:
    """The robots and places an instruction may name."""

    def __init__(self, robots: Iterable[RobotInfo] = (), places: Iterable[Place] = (), version: str = "0"):
        self.version = version
        self.robots = list(robots)
        self.places = list(places)
        self.kinds: dict[str, tuple[str, ...]] = {}
        for robot in self.robots:
            for word in kind_words(robot.model, robot.drive):
                self.kinds[word] = (*self.kinds.get(word, ()), robot.name)


class Grammar:
    """One phrase table for an ontology snapshot and a fleet, plus a bounded typo memo."""

    MEMO_LIMIT = 20_000

    def __init__(self, lexicon: Lexicon, fleet: Fleet):
        self.lexicon = lexicon
        self.fleet = fleet
        self.table: dict[tuple[str, ...], list[Meaning]] = {}
        self._add_grammar()
        for key, meaning in lexicon.action_phrases.items():
            self._add(key, meaning)
        for key, meaning in lexicon.concept_phrases.items():
            self._add(key, meaning)
        self._add_classwords(lexicon)
        self._add_fleet(fleet)
        self.max_len = max((len(k) for k in self.table), default=1)
        self.fuzzy_words = sorted(
            {k[0] for k, ms in self.table.items() if len(k) == 1 and self._fuzzable(k[0], ms)}
        )
        self._memo: dict[str, Meaning | None] = {}

    @staticmethod
    def _fuzzable(word: str, meanings: list[Meaning]) -> bool:
        kinds = {m.kind for m in meanings}
        return len(word) >= 4 and word.isalpha() and not kinds & {"PLACE", "NUMBER", "TIMES", "UNIT"}

    def _add(self, key: tuple[str, ...], meaning: Meaning) -> None:
        if key:
            self.table.setdefault(key, []).append(meaning)

    def _add_grammar(self) -> None:
        for kind, spec in GRAMMAR.items():
            for phrase in spec.split("|"):
                self._add(phrase_key(phrase) or (phrase,), Meaning(kind, phrase))
        for canonical, spec in SPEED_PHRASES.items():
            for phrase in spec.split("|"):
                self._add(phrase_key(phrase), Meaning("SPEED", canonical))
        for word, n in COUNT_WORDS.items():
            self._add(phrase_key(word), Meaning("NUMBER", float(n)))
        for word, unit in UNITS.items():
            self._add(phrase_key(word) or (word,), Meaning("UNIT", unit))
        for phrase, direction in DIRECTIONS.items():
            self._add(phrase_key(phrase), Meaning("DIRECTION", direction))
        for word in FILLERS:
            self._add((word,), Meaning("FILLER", word))

    def _add_classwords(self, lexicon: Lexicon) -> None:
        for cls in lexicon.map_classes:
            word = cls.casefold()
            for form in {word, *plural_forms(word)}:
                self._add((form,), Meaning("CLASSWORD", cls))

    def _add_fleet(self, fleet: Fleet) -> None:
        for robot in fleet.robots:
            for key in key_variants(robot.name):
                self._add(key, Meaning("ROBOT", robot.name))
        for word, names in fleet.kinds.items():
            for form in {word, *plural_forms(word)}:
                plural = form != word
                self._add(phrase_key(form), Meaning("KIND", (word, names, plural)))
        for place in fleet.places:
            for key in key_variants(place.name):
                self._add(key, Meaning("PLACE", place))

    def correct(self, word: str) -> Meaning | None:
        """Return the meaning of a word with one small typo, or None when unsure."""
        if word in self._memo:
            return self._memo[word]
        meaning = self._correct(word)
        if len(self._memo) >= self.MEMO_LIMIT:
            self._memo.clear()
        self._memo[word] = meaning
        return meaning

    def _correct(self, word: str) -> Meaning | None:
        stem = self._inflection(word)
        if stem is not None:
            return stem
        if len(word) < 4 or not word.isalpha() or word in COMMON_WORDS:
            return None
        hits = process.extract(word, self.fuzzy_words, scorer=OSA.distance, score_cutoff=2, limit=3)
        good = [(cand, dist) for cand, dist, _ in hits if _close_enough(word, cand, dist)]
        if not good:
            return None
        best = min(d for _, d in good)
        targets = {_primary(self.table[(c,)]) for c, d in good if d == best}
        if len(targets) != 1:
            return None
        return targets.pop()

    def _inflection(self, word: str) -> Meaning | None:
        """Map 'moving', 'moves', 'cleaned' to the action they inflect."""
        for suffix, repl in (("ing", ""), ("ing", "e"), ("es", ""), ("s", ""), ("ed", ""), ("ed", "e")):
            if word.endswith(suffix) and len(word) - len(suffix) >= 2:
                base = word[: -len(suffix)] + repl
                meanings = [m for m in self.table.get((base,), []) if m.kind == "ACTION"]
                if meanings:
                    return meanings[0]
        return None


def _primary(meanings: list[Meaning]) -> Meaning:
    order = (
        "ROBOT",
        "ACTION",
        "KIND",
        "CONCEPT",
        "SPEED",
        "CLASSWORD",
        "PREP",
        "ALL",
        "THEN",
        "AND",
        "DIRECTION",
        "UNIT",
        "EXCEPT",
        "ANY",
        "NOT",
        "FOREVER",
        "FILLER",
    )
    return min(meanings, key=lambda m: order.index(m.kind) if m.kind in order else len(order))


def _close_enough(word: str, cand: str, dist: int) -> bool:
    """Accept a typo only when it is clearly one: same first letter, few edits for the length."""
    if dist == 0 or (word[0] != cand[0] and word[:2] != cand[1::-1]):
        return False
    if len(cand) <= 4:
        return dist == 1 and len(word) == len(cand) and sorted(word) == sorted(cand)
    if len(cand) <= 7:
        return dist == 1
    return dist <= 2
