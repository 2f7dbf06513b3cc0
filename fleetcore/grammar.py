"""The instruction grammar's own words, and so the names a robot must not bear (no Django).

The interpreter's phrase table is built from these (interpreter/lexicon.py), with the step contract's unit and
direction words (fleetcore/steps.py) and the actions' names and synonyms (fleetcore/actions.py). A robot's name
goes into the same table, and the parser reads a name before any grammar word, so a robot called "from" or
"afterwards" would turn "move husky from A" into another sentence. `reserved` refuses every such word as a
name; it is derived from the tables the parser reads, so a word added to the grammar is refused at once.
Fillers ("please", "the", "spot") are not keywords: the parser drops them, and a name may be one ("Spot").
"""

from __future__ import annotations

import re

from fleetcore import actions
from fleetcore.steps import DIRECTIONS, UNITS

# The phrases of each speed word of the step contract (fleetcore.speed.SPEEDS): one key each, no more.
SPEED_PHRASES = {
    "very slow": "very slowly|very slow|really slowly|extremely slowly|at a crawl",
    "slow": "slowly|slow|carefully|gently|cautiously|slower",
    "normal": "normally|normal speed|at normal speed",
    "fast": "fast|quickly|quick|rapidly|swiftly|faster|hurry|speedily",
    "very fast": "very fast|very quickly|really fast|full speed|at full speed|top speed|max speed"
    "|as fast as possible|as fast as you can|asap",
}
# The grammar's classes of words: each a kind of item the parser reads (ALL, THEN, PREP, ...), its phrases.
GRAMMAR = {
    "ALL": "all|every|each|everyone|everybody|everything|whole fleet|the whole fleet|fleet|all of you",
    "THEN": "then|and then|after that|and after that|afterwards|next|and next|later|finally|followed by",
    "AND": "and|plus|also|as well as|&",
    "TIMES": "times|time|x|rounds|round|turns|laps|loops",
    "PREP": "to|towards|toward|into|in to|at|till|until|onto|unto|on|up to|over to|as far as|in|inside|from|between",
    "EXCEPT": "except|except for|but|but not|other than|apart from|besides|excluding|save for|not including",
    "ANY": "any|any one|anyone|anybody|someone|somebody|whichever|nearest|the nearest|closest|the closest"
    "|nearest free|the nearest free|closest free|the closest free|a free|any free|any available|an available"
    "|first free|the first free|one of the|any one of the|any of the|a single",
    "NOT": "not|do not|don't|don’t|dont|never|without|no|do n't|please don't|please do not|must not|mustn't",
    "FOREVER": "until stopped|until i say stop|until told to stop|until told otherwise|until further notice"
    "|forever|continuously|indefinitely|nonstop|non-stop|endlessly|over and over|again and again|on repeat"
    "|in a loop|until i stop you|until you are stopped|until stop|until i say so|all day|round the clock",
    "FILLER": "right now|right away|first|firstly|for|by|doing|do|done|please first|to start with"
    "|instruction|instructions|number",
}
FILLER = "FILLER"  # the one class of GRAMMAR that is no keyword: its words are dropped
COUNT_WORDS = {
    "once": 1, "twice": 2, "thrice": 3, "one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6,
    "seven": 7, "eight": 8, "nine": 9, "ten": 10, "eleven": 11, "twelve": 12, "thirteen": 13, "fourteen": 14,
    "fifteen": 15, "sixteen": 16, "seventeen": 17, "eighteen": 18, "nineteen": 19, "twenty": 20, "thirty": 30,
    "forty": 40, "fifty": 50, "sixty": 60, "seventy": 70, "eighty": 80, "ninety": 90, "hundred": 100,
    "half": 0.5, "quarter": 0.25, "a hundred": 100, "one hundred": 100,
}  # fmt: skip


def _phrases(spec: str) -> list[str]:
    return spec.split("|")


def _action_words() -> set[str]:
    """Each action's name ("make way" for make_way) and its synonyms, as the ontology is seeded with them."""
    words = set()
    for action in actions.ACTIONS.values():
        words.update({action.name, action.name.replace("_", " "), *action.synonyms})
    return words


def keywords() -> frozenset[str]:
    """Every phrase the parser reads as grammar (lower case; words joined by one space)."""
    words = {phrase for kind, spec in GRAMMAR.items() if kind != FILLER for phrase in _phrases(spec)}
    words.update(phrase for spec in SPEED_PHRASES.values() for phrase in _phrases(spec))
    words.update(COUNT_WORDS, UNITS, DIRECTIONS, _action_words())
    return frozenset(" ".join(phrase.casefold().split()) for phrase in words)


RESERVED = keywords()


def reserved(name: str) -> bool:
    """Whether a robot name would read as grammar: one keyword ("from"), or one said with dashes ("up-to")."""
    said = " ".join(re.split(r"[-_]+", name.casefold())).strip()
    return said in RESERVED or name.casefold() in RESERVED
