"""Understand a person's answer to a question: what it teaches the ontology (no Django)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from interpreter.tokens import normalize, tokenize

EXAMPLES = (
    "proceed means move",
    "hurry is a synonym of move",
    "sea is not a place",
    "sea is a location at (3, 4)",
    "forget hurry",
)
_WORD = r"(?P<w>[^\W\d_][\w' -]{0,39}?)"
_PATTERNS = (
    ("forget", re.compile(rf"^(?:forget|unlearn|remove)\s+(?:the\s+word\s+)?{_WORD}$")),
    (
        "not_a_place",
        re.compile(
            rf"^{_WORD}\s+(?:is|are)\s+(?:not|n't|never)\s+(?:a\s+|an\s+)?(?:valid\s+)?"
            r"(?:place|location|destination|room|waypoint|somewhere)\b.*$"
        ),
    ),
    ("not_a_place", re.compile(rf"^{_WORD}\s+(?:is|are)\s+nowhere\b.*$")),
    (
        "location",
        re.compile(
            rf"^{_WORD}\s+(?:is|are)\s+(?:a\s+|an\s+|the\s+)?(?:location|place|waypoint|room|point|spot)\s+"
            r"(?:at|on|in)\s+(?P<where>.+)$"
        ),
    ),
    ("location", re.compile(rf"^{_WORD}\s+(?:is|are)\s+at\s+(?P<where>.*\d.*)$")),
    (
        "synonym",
        re.compile(
            rf"^{_WORD}\s+(?:means|=|is\s+the\s+same\s+as|is\s+a\s+synonym\s+(?:of|for)|"
            r"is\s+another\s+word\s+for|equals|is\s+like)\s+(?P<m>.+)$"
        ),
    ),
)


@dataclass(frozen=True)
class Answer:
    """What an answer teaches: kind is synonym, not_a_place, location or forget."""

    kind: str
    word: str
    meaning: str = ""
    x: float | None = None
    y: float | None = None


def parse_answer(text: str) -> Answer:
    """Return what the answer teaches; raise ValueError with a helpful message when it is not understood."""
    clean = re.sub(r"(?<!\w)['‘’]|['‘’](?!\w)|[\"“”]", " ", normalize(text or "").casefold())
    clean = " ".join(clean.split()).strip(" .!?;:")
    clean = re.sub(r"^(?:ok|okay|yes|no|well)[, ]+", "", clean)
    for kind, pattern in _PATTERNS:
        m = pattern.match(clean)
        if m:
            return _answer(kind, m)
    raise ValueError("I did not understand that answer.")


def _answer(kind: str, m: re.Match) -> Answer:
    word = " ".join(m.group("w").strip(" '").split())
    if not word or len(word.split()) > 3:
        raise ValueError("Teach one word or a short phrase (at most three words) at a time.")
    if kind == "synonym":
        meaning = " ".join(m.group("m").strip(" '").split())
        meaning = re.sub(r"^(?:to|the|a|an)\s+", "", meaning)
        return Answer(kind, word, meaning)
    if kind == "location":
        coords = [t for t in tokenize(m.group("where")) if t[0] in "CN" and t[2] is not None]
        point = _point(coords)
        if point is None:
            raise ValueError(f"Where is {word}? Give coordinates, e.g. '{word} is a location at (3, 4)'.")
        return Answer(kind, word, f"({point[0]:g}, {point[1]:g})", *point)
    return Answer(kind, word)


def _point(tokens) -> tuple[float, float] | None:
    if tokens and tokens[0][0] == "C":
        return tokens[0][2]
    numbers = [t[2] for t in tokens if t[0] == "N"]
    return (numbers[0], numbers[1]) if len(numbers) >= 2 else None
