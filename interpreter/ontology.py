"""The robot ontology in owlready2, built from the editable terms; OWL RDF/XML export and import (no Django).

Owlready2 is slow to build and to query, so the service builds it once per ontology version (in a fresh
World each time, never the default_world) and hands the parser a plain snapshot (`interpreter.lexicon.Lexicon`)
read back from the OWL classes, sameAs individuals and allValuesFrom restrictions.
"""

from __future__ import annotations

import io
import re
import types
from pathlib import Path

import owlready2 as owl

from interpreter.lexicon import Lexicon
from interpreter.terms import ActionTerm, ClassTerm, ConceptTerm, KeywordTerm, SynonymTerm, Terms

IRI = "http://rosfleet.local/ontology/robots.owl"
NS = IRI + "#"
_DRIVES = {"wheeled": "WheeledRobot", "legged": "LeggedRobot", "other": "OtherRobot"}


def _camel(name: str) -> str:
    return "".join(p[:1].upper() + p[1:] for p in re.split(r"[^0-9A-Za-z]+", name) if p) or "Unnamed"


def _slug(word: str) -> str:
    return re.sub(r"[^0-9A-Za-z]+", "_", word.casefold()).strip("_") or "x"


def _declare_schema(onto) -> None:
    """Declare the fixed vocabulary: robots, actions, destinations, properties."""
    with onto:
        robot = types.new_class("Robot", (owl.Thing,))
        for name in _DRIVES.values():
            types.new_class(name, (robot,))
        types.new_class("Action", (owl.Thing,))
        types.new_class("TopicKeyword", (owl.Thing,))
        for name in ("category", "keywordText", "forAction"):
            types.new_class(name, (owl.DataProperty, owl.FunctionalProperty)).range = [str]
        for name in ("takesDestination", "requiresDestination", "countable", "isCanonical"):
            types.new_class(name, (owl.DataProperty, owl.FunctionalProperty)).range = [bool]
        types.new_class("keywordWeight", (owl.DataProperty, owl.FunctionalProperty)).range = [float]
        types.new_class("onMap", (owl.AnnotationProperty,))
        types.new_class("hasDestination", (owl.ObjectProperty,))


def build(terms: Terms) -> owl.Ontology:
    """Build the ontology from terms in a new World; return the ontology."""
    world = owl.World()
    onto = world.get_ontology(IRI)
    _declare_schema(onto)
    with onto:
        classes = _add_classes(onto, terms.classes)
        actions = _add_actions(onto, terms.actions, classes)
        concepts = _add_concepts(onto, terms.concepts, classes)
        _add_synonyms(onto, terms.synonyms, actions, concepts)
        _add_keywords(onto, terms.keywords)
        _add_robot_models(onto, terms.robot_models)
    onto.hasDestination.domain = [onto.Action]
    return onto


def _add_classes(onto, class_terms: list[ClassTerm]) -> dict[str, type]:
    made: dict[str, type] = {}
    pending = list(class_terms)
    while pending:
        progressed = False
        for term in list(pending):
            parent = made.get(term.parent) if term.parent else owl.Thing
            if parent is None and term.parent in {t.name for t in pending}:
                continue
            cls = types.new_class(_camel(term.name), (parent or owl.Thing,))
            cls.label = [term.name]
            cls.onMap = [term.on_map]
            cls.comment = [term.description] if term.description else []
            made[term.name] = cls
            pending.remove(term)
            progressed = True
        if not progressed:  # a cycle: attach the rest to Thing
            for term in pending:
                made[term.name] = types.new_class(_camel(term.name), (owl.Thing,))
                made[term.name].label = [term.name]
            break
    roots = [c for t, c in made.items() if c.is_a == [owl.Thing]]
    onto.hasDestination.range = roots[:1]
    return made


def _add_actions(onto, action_terms: list[ActionTerm], classes: dict[str, type]) -> dict[str, object]:
    individuals = {}
    for term in action_terms:
        cls = types.new_class(_camel(term.name), (onto.Action,))
        cls.label = [term.name]
        accepted = [classes[name] for name in term.accepts if name in classes]
        if term.takes_destination and accepted:
            target = accepted[0] if len(accepted) == 1 else owl.Or(accepted)
            cls.is_a.append(onto.hasDestination.only(target))  # owl:allValuesFrom
        elif not term.takes_destination:
            cls.is_a.append(onto.hasDestination.max(0))
        ind = cls(
            f"action_{_slug(term.name)}",
            label=[term.name],
            comment=[term.description] if term.description else [],
        )
        ind.category = term.category
        ind.takesDestination = term.takes_destination
        ind.requiresDestination = term.requires_destination
        ind.countable = term.countable
        ind.isCanonical = True
        individuals[term.name] = ind
    return individuals


def _add_concepts(onto, concept_terms: list[ConceptTerm], classes: dict[str, type]) -> dict[str, object]:
    out = {}
    for term in concept_terms:
        cls = classes.get(term.cls)
        if cls is None:
            continue
        ind = cls(f"concept_{_slug(term.name)}", label=[term.name])
        ind.comment = [term.description] if term.description else []
        ind.isCanonical = True
        out[term.name] = ind
    return out


def _add_synonyms(onto, synonyms: list[SynonymTerm], actions: dict, concepts: dict) -> None:
    for term in synonyms:
        target = actions.get(term.action) if term.action else concepts.get(term.concept)
        if target is None:
            continue
        ind = target.__class__(f"word_{_slug(term.word)}", label=[term.word])
        ind.isCanonical = False
        ind.equivalent_to.append(target)  # owl:sameAs


def _add_keywords(onto, keywords: list[KeywordTerm]) -> None:
    for term in keywords:
        ind = onto.TopicKeyword(f"keyword_{_slug(term.action)}_{_slug(term.keyword)}")
        ind.forAction, ind.keywordText, ind.keywordWeight = term.action, term.keyword, float(term.weight)


def _add_robot_models(onto, robot_models: list[tuple[str, str]]) -> None:
    for model, drive in sorted(set(robot_models)):
        if model:
            parent = getattr(onto, _DRIVES.get(drive, "OtherRobot"))
            cls = types.new_class("Model" + _camel(model), (parent,))
            cls.label = [model]


# --- reading the ontology back --------------------------------------------------------------------------


def _label(entity) -> str:
    return str(entity.label[0]) if entity.label else entity.name


def extract_terms(onto) -> Terms:
    """Read the terms back from an ontology (built here or imported from RDF/XML)."""
    classes, class_names = _extract_classes(onto)
    actions, synonyms = [], []
    for cls in onto.Action.subclasses():
        actions.append(_extract_action(onto, cls, class_names))
    concepts = []
    for cls in class_names:
        for ind in cls.instances():
            if ind.isCanonical and cls in ind.is_a:
                concepts.append(ConceptTerm(_label(ind), class_names[cls], _first(ind.comment)))
    for ind in onto.individuals():
        if ind.isCanonical is False:
            synonyms.extend(_extract_synonym(onto, ind))
    keywords = [
        KeywordTerm(k.forAction, k.keywordText, float(k.keywordWeight or 1.0))
        for k in onto.TopicKeyword.instances()
    ]
    models = [(_label(c), _drive_of(onto, c)) for c in onto.Robot.descendants() if c.name.startswith("Model")]
    return Terms(actions, classes, concepts, synonyms, keywords, models)


def _extract_classes(onto) -> tuple[list[ClassTerm], dict]:
    skip = {onto.Robot, onto.Action, onto.TopicKeyword, *onto.Robot.descendants(), *onto.Action.descendants()}
    names = {c: _label(c) for c in onto.classes() if c not in skip}
    terms = []
    for cls, name in names.items():
        parents = [p for p in cls.is_a if p in names]
        on_map = bool(cls.onMap and cls.onMap[0] in (True, "true", "True", 1))
        terms.append(ClassTerm(name, names[parents[0]] if parents else None, on_map, _first(cls.comment)))
    return terms, names


def _extract_action(onto, cls, class_names: dict) -> ActionTerm:
    ind = next((i for i in cls.instances() if i.isCanonical), None)
    accepts: list[str] = []
    for restriction in cls.is_a:
        if isinstance(restriction, owl.Restriction) and restriction.type == owl.ONLY:
            value = restriction.value
            targets = value.Classes if isinstance(value, owl.Or) else [value]
            accepts.extend(class_names[t] for t in targets if t in class_names)
    return ActionTerm(
        _label(cls),
        (ind.category if ind else None) or "motion",
        bool(ind and ind.takesDestination),
        bool(ind and ind.requiresDestination),
        bool(ind and ind.countable),
        tuple(accepts),
        _first(ind.comment) if ind else "",
    )


def _extract_synonym(onto, ind) -> list[SynonymTerm]:
    for target in ind.equivalent_to:
        if getattr(target, "isCanonical", None):
            if isinstance(target, onto.Action):
                return [SynonymTerm(_label(ind), action=_label(target.__class__))]
            return [SynonymTerm(_label(ind), concept=_label(target))]
    return []


def _drive_of(onto, cls) -> str:
    for drive, name in _DRIVES.items():
        if issubclass(cls, getattr(onto, name)):
            return drive
    return "other"


def _first(values) -> str:
    return str(values[0]) if values else ""


def snapshot(terms: Terms, version: str = "0") -> Lexicon:
    """Build the OWL ontology and read the parser's plain snapshot from it."""
    onto = build(terms)
    try:
        return Lexicon(extract_terms(onto), version)
    finally:
        onto.world.close()


def export_rdfxml(terms: Terms) -> bytes:
    """Return the ontology as OWL RDF/XML."""
    onto = build(terms)
    try:
        buffer = io.BytesIO()
        onto.save(file=buffer, format="rdfxml")
        return buffer.getvalue()
    finally:
        onto.world.close()


def import_rdfxml(data: bytes | str | Path) -> Terms:
    """Read terms from OWL RDF/XML (bytes or a path); raise ValueError when it is not our ontology."""
    if isinstance(data, Path | str) and not (isinstance(data, str) and data.lstrip().startswith("<")):
        data = Path(data).read_bytes()
    if isinstance(data, str):
        data = data.encode()
    world = owl.World()
    try:
        onto = world.get_ontology(IRI).load(fileobj=io.BytesIO(data))
        if onto.Action is None or onto.TopicKeyword is None:
            raise ValueError("not a robots ontology exported by this system (no Action class)")
        return extract_terms(onto)
    except ValueError:
        raise
    except Exception as exc:  # owlready2 raises many kinds of parse errors
        raise ValueError(f"cannot read the ontology: {exc}") from exc
    finally:
        world.close()
