"""The first passes of the parser: text -> tokens (a regex) -> items (the longest phrase of the Grammar's table
at each position, typos corrected, number words joined). No Django; linear in the length of the text.

The parser (interpreter/parser.py) fills step drafts from the items; the answers to questions
(interpreter/lessons.py) read the same tokens.
"""

from __future__ import annotations

import math
import re
import unicodedata
from dataclasses import dataclass

from interpreter.lexicon import Grammar, Meaning

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


# Which meaning of an ambiguous phrase wins: in this order, and after a preposition in _DEST_ORDER's.
_ORDER = (
    "ROBOT", "ACTION", "PLACE", "KIND", "CONCEPT", "SPEED", "PREP", "ALL", "THEN", "AND",
    "NUMBER", "TIMES", "UNIT", "DIRECTION", "EXCEPT", "ANY", "NOT", "FOREVER", "CLASSWORD", "FILLER",
)  # fmt: skip
_DEST_ORDER = ("PLACE", "CONCEPT", "CLASSWORD", "ROBOT", "ACTION", "KIND", "SPEED", *_ORDER[5:])


@dataclass(slots=True)
class Item:
    kind: str
    value: object
    text: str
    synonym: str | None = None
    corrected_from: str | None = None


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


class Lexer:
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
        owner = self._possessive(text)
        if owner is not None:  # "husky's instruction": the robot
            self._emit(Item("ROBOT", owner.value, text))
            return 1
        if kind == "N":
            self._emit(Item("NUMBER", value, text) if value is not None else Item("UNKNOWN", None, text))
            return 1
        meaning = self.grammar.correct(text)
        if meaning is None:
            self._emit_unknown(text)
        else:
            self._emit(Item(meaning.kind, meaning.value, text, meaning.synonym, corrected_from=text))
        return 1

    def _possessive(self, text: str) -> Meaning | None:
        """The robot a possessive names ("husky's"), or None."""
        if not text.endswith(("'s", "’s")):
            return None
        return next((m for m in self.grammar.table.get((text[:-2],), ()) if m.kind == "ROBOT"), None)

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


def merge_numbers(items: list[Item]) -> list[Item]:
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
