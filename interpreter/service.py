"""The interpreter for the rest of the project: interpret(), read(), teach(), warm_up(), export and import.

Each process keeps one Store: the parser's snapshot of the ontology (built through owlready2 once per
ontology version) and the phrase table for the current fleet. Every call compares the version tokens in
the cache with the ones it was built from, so an edit anywhere takes effect on the next instruction.
"""

from __future__ import annotations

import functools
import logging
import threading

from django.db import transaction

from audit import records as audit
from fleetcore.interpretation import Interpretation
from interpreter import models as m
from interpreter import ontology, versions
from interpreter.lessons import EXAMPLES, Answer, parse_answer
from interpreter.lexicon import Fleet, Grammar, Lexicon, Place, RobotInfo, phrase_key
from interpreter.models import (
    ActionConcept,
    DestinationClass,
    DestinationConcept,
    Lesson,
    Synonym,
    load_terms,
)
from interpreter.parser import interpret as parse
from interpreter.terms import Terms
from places.models import Location, Map
from robots.models import Robot

log = logging.getLogger(__name__)
_PLACE_CLASSES = {"room": "Room", "waypoint": "Waypoint"}


class Store:
    """The per-process ontology snapshot and grammar, rebuilt when a version token changes."""

    def __init__(self):
        self.lock = threading.Lock()
        self.local_changes = versions.LOCAL_CHANGES  # this process's own edits (the same list)
        self.reset()

    def reset(self) -> None:
        self.lexicon: Lexicon | None = None
        self.grammar: Grammar | None = None
        self.onto_token: str | None = None
        self.fleet_token: str | None = None
        self.builds = 0

    def get_grammar(self) -> Grammar:
        try:
            onto_token, fleet_token = versions.current()
        except Exception as exc:  # Redis away or refusing writes: the grammar this process has, or one afresh
            log.warning("interpreter: version tokens not read (%r); the grammar as it is", exc)
            onto_token, fleet_token = self.onto_token or "offline", self.fleet_token or "offline"
        with self.lock:
            changes = set(self.local_changes)
            self.local_changes.clear()
            if self.lexicon is None or "ontology" in changes or onto_token != self.onto_token:
                self.lexicon = ontology.snapshot(_load_terms(), onto_token)
                self.onto_token, self.grammar = onto_token, None
                self.builds += 1
                log.info("ontology snapshot built (token %s)", onto_token)
            if self.grammar is None or "fleet" in changes or fleet_token != self.fleet_token:
                self.grammar = Grammar(self.lexicon, load_fleet(fleet_token))
                self.fleet_token = fleet_token
            return self.grammar


@functools.cache
def store() -> Store:
    """Return this process's store (created on first use, never at import time)."""
    return Store()


def _load_terms() -> Terms:

    return load_terms()


def load_fleet(version: str = "0") -> Fleet:
    """Read robot names, kinds and named locations from the database."""

    robots = [RobotInfo(*row) for row in Robot.objects.values_list("name", "model", "drive")]
    places, seen = [], set()
    for name, x, y, kind in Location.objects.order_by("map_id", "name").values_list("name", "x", "y", "kind"):
        if name.casefold() not in seen:
            seen.add(name.casefold())
            places.append(Place(name, float(x), float(y), _PLACE_CLASSES.get(kind, "Location")))
    return Fleet(robots, places, version)


def interpret(text: str) -> Interpretation:
    """Interpret one instruction with the grammar as it is now (its version tokens checked)."""
    return parse(text, store().get_grammar())


def read(text: str) -> Interpretation:
    """The text parsed once, for `submit` and the page's socket: with the grammar this process already has (no
    Redis on the way), so a stop is known at once whatever Redis does; anything else is kept when that grammar
    is still the current one, and parsed again only when the ontology or the fleet changed meanwhile."""
    had = store().grammar
    if had is None:
        return interpret(text)
    quick = parse(text, had)
    if quick.is_stop:
        return quick
    current = store().get_grammar()
    return quick if current is had else parse(text, current)


def warm_up() -> None:
    """Build the ontology snapshot and grammar now (a Celery worker calls this at process start)."""
    try:
        store().get_grammar()
    except Exception:  # a worker must start even when the database is not migrated yet
        log.exception("interpreter warm-up failed; the ontology will load on first use")


# --- teaching ---------------------------------------------------------------------------------------


def teach(answer_text: str, user=None, instruction=None) -> dict:
    """Learn from a person's answer; store the lesson (who, when) and audit it."""
    asked = _asked(instruction)
    try:
        answer = _bare_answer(answer_text, asked) or parse_answer(answer_text)
        with transaction.atomic():
            meaning = _TEACHERS[answer.kind](answer, store().get_grammar())
            lesson = _record_lesson(answer_text, answer, meaning, user, instruction)
    except ValueError as exc:
        examples = _examples_about(asked) or list(EXAMPLES)
        return {"ok": False, "message": f"{exc} Try e.g. '{examples[0]}'.", "examples": examples}
    result = {
        "ok": True,
        "kind": answer.kind,
        "word": answer.word,
        "meaning": meaning,
        "lesson_id": lesson.pk,
        "message": _TAUGHT_WORDS[answer.kind].format(w=answer.word, m=meaning),
        "ontology_version": versions.ontology_number(),
    }
    if lesson.instruction is not None:
        result["instruction"] = interpret(lesson.instruction.text).to_dict()
    return result


def _asked(instruction):
    """What the question of this instruction asked about (the parser's first problem with a word), or None."""

    pk = getattr(instruction, "pk", instruction)
    if pk is None:
        return None
    instructions = Lesson._meta.get_field("instruction").related_model  # by the foreign key: no upward import
    text = instructions.objects.filter(pk=pk).values_list("text", flat=True).first()
    if text is None:
        return None
    return next((p for p in interpret(text).problems if p.word), None)


def _bare_answer(text: str, asked) -> Answer | None:
    """A bare word answering a question about a word ("move", asked what 'zoom' is) means "zoom means move"."""
    words = " ".join((text or "").strip(" .!?'\"").split())
    if asked is None or asked.code not in _BARE or not words or len(words.split()) > 3:
        return None
    if not words.replace(" ", "").isalpha():
        return None
    try:
        parse_answer(words)
    except ValueError:
        return Answer("synonym", asked.word, words.casefold())
    return None  # a full answer ("zoom means move") parses as it is


_BARE = {"unknown_action", "unknown_destination", "unknown_word", "no_such_place"}


def _examples_about(asked) -> list[str]:
    """Answers that fit what was asked: about the word asked, in the forms that question takes."""
    if asked is None:
        return []
    w = asked.word
    forms = {
        "unknown_action": [f"{w} means move", f"{w} is a synonym of navigate"],
        "unknown_destination": [f"{w} means A", f"{w} is a location at (3, 4)", f"{w} is not a place"],
        "no_such_place": [f"{w} means A", f"{w} is a location at (3, 4)"],
        "unlocated": [f"{w} is a location at (3, 4)"],
        "unknown_word": [f"{w} means move", f"{w} is not a place"],
    }.get(asked.code, [])
    return list(dict.fromkeys([e for e in (asked.example, *forms) if e]))


_TAUGHT_WORDS = {
    "synonym": "Learned: '{w}' means '{m}'.",
    "not_a_place": "Learned: '{w}' is not a place robots can go to.",
    "location": "Learned: '{w}' is a location at {m}.",
    "forget": "Forgot '{w}'.",
}


def _known(grammar: Grammar, word: str) -> list:
    return [m for m in grammar.table.get(phrase_key(word), []) if m.kind not in {"FILLER"}]


def _teach_synonym(answer: Answer, grammar: Grammar) -> str:

    targets = {m.kind: m for m in _known(grammar, answer.meaning)}
    already = {m.kind: m for m in _known(grammar, answer.word)}
    if "ACTION" in targets:
        target = targets["ACTION"].value
        _refuse_if_known(answer.word, already, ("ACTION", target))
        Synonym.objects.create(word=answer.word, action=ActionConcept.objects.get(name=target))
        return str(target)
    if "CONCEPT" in targets:
        target = targets["CONCEPT"].value
        _refuse_if_known(answer.word, already, ("CONCEPT", target))
        Synonym.objects.create(word=answer.word, concept=DestinationConcept.objects.get(name=target))
        return str(target)
    if "PLACE" in targets:
        _refuse_if_known(answer.word, already, None)
        place = targets["PLACE"].value
        _create_location(answer.word, place.x, place.y, like=place.name)
        return place.name
    known = ", ".join(sorted(grammar.lexicon.actions))
    raise ValueError(
        f"I don't know '{answer.meaning}' either. Say which action or place it means (actions: {known})."
    )


def _refuse_if_known(word: str, already: dict, same: tuple | None) -> None:
    for kind, meaning in already.items():
        if same and (kind, meaning.value) == same:
            raise ValueError(f"I already know that '{word}' means '{meaning.value}'.")
        if kind in {"ACTION", "CONCEPT", "PLACE", "ROBOT", "KIND"}:
            what = getattr(meaning.value, "name", meaning.value)
            raise ValueError(
                f"'{word}' already means something else ({kind.lower()} {what}); say 'forget {word}' first."
            )


def _teach_not_a_place(answer: Answer, grammar: Grammar) -> str:

    _refuse_if_known(answer.word, {m.kind: m for m in _known(grammar, answer.word)}, None)
    cls = (
        DestinationClass.objects.filter(name="Taught").first()
        or DestinationClass.objects.filter(on_map=False).exclude(parent=None).first()
    )
    if cls is None:
        raise ValueError("The ontology has no class for things that are not places; add one in the admin.")
    DestinationConcept.objects.create(
        name=answer.word, destination_class=cls, description="taught by a person"
    )
    return cls.name


def _teach_location(answer: Answer, grammar: Grammar) -> str:
    _refuse_if_known(answer.word, {m.kind: m for m in _known(grammar, answer.word)}, None)
    _create_location(answer.word, answer.x, answer.y)
    return answer.meaning


def _create_location(name: str, x: float, y: float, like: str | None = None) -> None:

    model = Location.objects.filter(name=like).first() if like else None
    the_map = model.map if model else Map.objects.order_by("-created_at").first()
    if the_map is None:
        raise ValueError("There is no map yet to put a location on; load a map first.")
    Location.objects.create(map=the_map, name=name, x=x, y=y, kind=Location.Kind.WAYPOINT)


def _teach_forget(answer: Answer, grammar: Grammar) -> str:

    deleted, _ = Synonym.objects.filter(word=answer.word).delete()
    if not deleted:
        deleted, _ = DestinationConcept.objects.filter(name=answer.word).delete()
    if not deleted:
        raise ValueError(f"'{answer.word}' is not a synonym or a concept I was taught.")
    return ""


_TEACHERS = {
    "synonym": _teach_synonym,
    "not_a_place": _teach_not_a_place,
    "location": _teach_location,
    "forget": _teach_forget,
}


def _record_lesson(text: str, answer: Answer, meaning: str, user, instruction):

    who = user if getattr(user, "is_authenticated", False) else None
    lesson = Lesson.objects.create(
        taught_by=who,
        text=text[:1000],
        kind=answer.kind,
        word=answer.word,
        meaning=meaning,
        instruction_id=getattr(instruction, "pk", instruction),
    )
    details = {"lesson": lesson.pk, "kind": answer.kind, "meaning": meaning, "text": text[:200]}
    if instruction is not None:
        details["instruction"] = lesson.instruction_id
    audit.record(user, "ontology.teach", answer.word, **details)
    return lesson


# --- export and import ------------------------------------------------------------------------------


def export_ontology() -> bytes:
    """Return the current ontology as OWL RDF/XML."""
    return ontology.export_rdfxml(_load_terms())


@transaction.atomic
def import_ontology(data: bytes | str) -> Terms:
    """Replace the editable terms with those of an OWL RDF/XML ontology; return them."""

    terms = ontology.import_rdfxml(data)
    if not terms.actions:
        raise ValueError("the ontology has no actions; refusing to import it")
    m.Synonym.objects.all().delete()
    m.DestinationConcept.objects.all().delete()
    m.ActionConcept.objects.all().delete()
    m.TopicKeyword.objects.all().delete()
    m.DestinationClass.objects.update(parent=None)
    m.DestinationClass.objects.all().delete()
    write_terms(terms, m)
    versions.bump_ontology()
    return terms


def write_terms(terms: Terms, models) -> None:
    """Create the terms' rows (models: a module or the migration's historical models)."""
    classes = {c.name: models.DestinationClass.objects.create(name=c.name, on_map=c.on_map, description=c.description)
               for c in terms.classes}  # fmt: skip
    for c in terms.classes:
        if c.parent in classes:
            classes[c.name].parent = classes[c.parent]
            classes[c.name].save(update_fields=["parent"])
    actions = {}
    for a in terms.actions:
        actions[a.name] = models.ActionConcept.objects.create(
            name=a.name, category=a.category, takes_destination=a.takes_destination,
            requires_destination=a.requires_destination, countable=a.countable, description=a.description,
        )  # fmt: skip
        actions[a.name].accepts.set([classes[n] for n in a.accepts if n in classes])
    concepts = {
        c.name: models.DestinationConcept.objects.create(
            name=c.name, destination_class=classes[c.cls], description=c.description
        )
        for c in terms.concepts
        if c.cls in classes
    }
    for s in terms.synonyms:
        if s.action in actions or s.concept in concepts:
            models.Synonym.objects.create(
                word=s.word, action=actions.get(s.action), concept=concepts.get(s.concept)
            )
    models.TopicKeyword.objects.bulk_create(
        [models.TopicKeyword(action=k.action, keyword=k.keyword, weight=k.weight) for k in terms.keywords]
    )
