"""A stop read at once, before the grammar is built: what a fresh process (the CLI) can tell in its first
milliseconds, so its zeros need not wait for the ontology.

Only the plainest stops are read here, with the words of the one vocabulary (the stop action's name and synonyms
in fleetcore/actions.py, the grammar's words in interpreter/lexicon.py): "stop", "halt everything", "please stop
husky and tiago". Anything more ("stop every robot except husky", "stop husky then ...") is None: the full
interpretation reads it, and the stop goes the usual way. The names are as typed (case-folded); whoever zeroes
them checks them against the robots it knows and zeroes nothing when one is not a robot.
"""

from __future__ import annotations

from functools import cache

from fleetcore.actions import ACTIONS
from interpreter.lexicon import FILLERS, WORD_RE, grammar_phrases, grammar_words, phrase_key


@cache
def _vocabulary() -> tuple[list[tuple[str, ...]], set[tuple[str, ...]], set[str], set[str]]:
    """(stop phrases, longest first; the "all" phrases; the "and" words; every other grammar word)."""
    stop = ACTIONS["stop"]
    phrases = sorted({phrase_key(p) for p in (stop.name, *stop.synonyms)}, key=len, reverse=True)
    joins = {word for phrase in grammar_phrases("AND") for word in phrase}
    return phrases, grammar_phrases("ALL"), joins, grammar_words() - joins


def stop_subject(text: str) -> list[str] | str | None:
    """The robots a plain stop names ("all" when none or "all"/"everything"), or None when it is no plain stop."""
    phrases, every, joins, grammar = _vocabulary()
    words = [word.casefold() for word in WORD_RE.findall(text or "")]
    while words and words[0] in FILLERS:
        words.pop(0)
    said = next((phrase for phrase in phrases if tuple(words[: len(phrase)]) == phrase), None)
    if said is None:
        return None
    rest = [word for word in words[len(said) :] if word not in FILLERS and word not in joins]
    if not rest or tuple(rest) in every:
        return "all"
    if any(word in grammar for word in rest):
        return None
    return rest
