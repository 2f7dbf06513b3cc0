"""The ontology's editable terms as plain data, and the seed the database starts from (no Django)."""

from __future__ import annotations

from dataclasses import dataclass, field

from fleetcore.actions import ACTIONS
from fleetcore.bindings import ROLES


@dataclass(frozen=True)
class ActionTerm:
    """An action concept: what robots can be told to do."""

    name: str
    category: str  # motion | task | control | query
    takes_destination: bool = False
    requires_destination: bool = False
    countable: bool = False  # a task that takes a count, e.g. rotate(5)
    accepts: tuple[str, ...] = ()  # destination classes (owl:allValuesFrom of hasDestination)
    description: str = ""


@dataclass(frozen=True)
class ClassTerm:
    """A destination class; on_map classes are places robots can go to."""

    name: str
    parent: str | None = None
    on_map: bool = False
    description: str = ""


@dataclass(frozen=True)
class ConceptTerm:
    """A thing people may name as a destination, e.g. roof (a BuildingPart, not a place on the map)."""

    name: str
    cls: str
    description: str = ""


@dataclass(frozen=True)
class SynonymTerm:
    """A word that is owl:sameAs an action or a destination concept."""

    word: str
    action: str | None = None
    concept: str | None = None


@dataclass(frozen=True)
class KeywordTerm:
    """A topic-name keyword the registration engine scores for an action."""

    action: str
    keyword: str
    weight: float = 1.0


@dataclass
class Terms:
    """Every editable term of the ontology."""

    actions: list[ActionTerm] = field(default_factory=list)
    classes: list[ClassTerm] = field(default_factory=list)
    concepts: list[ConceptTerm] = field(default_factory=list)
    synonyms: list[SynonymTerm] = field(default_factory=list)
    keywords: list[KeywordTerm] = field(default_factory=list)
    robot_models: list[tuple[str, str]] = field(default_factory=list)  # (model, drive)

    def sorted(self) -> Terms:
        """Return a copy in a canonical order, for comparing two sets of terms."""
        return Terms(
            actions=sorted(self.actions, key=lambda t: t.name),
            classes=sorted(self.classes, key=lambda t: t.name),
            concepts=sorted(self.concepts, key=lambda t: t.name),
            synonyms=sorted(self.synonyms, key=lambda t: t.word),
            keywords=sorted(self.keywords, key=lambda t: (t.action, t.keyword)),
            robot_models=sorted(set(self.robot_models)),
        )


LOCATION_ACTIONS = ("Location",)

SEED_CLASSES = [
    ClassTerm("Destination", None, False, "anything a person may name as where to go"),
    ClassTerm("Location", "Destination", True, "a place on the map"),
    ClassTerm("Room", "Location", True, "a room on the map"),
    ClassTerm("Waypoint", "Location", True, "a named point on the map"),
    ClassTerm("Point", "Location", True, "coordinates on the map"),
    ClassTerm("NotAPlace", "Destination", False, "something robots cannot go to"),
    ClassTerm("BuildingPart", "NotAPlace", False, "a part of a building, not a place on the floor"),
    ClassTerm("CelestialThing", "NotAPlace", False, "something in the sky"),
    ClassTerm("Taught", "NotAPlace", False, "a word a person said is not a place"),
]

# The actions, their synonyms and the topic keywords come from the one registry of each (fleetcore).
SEED_ACTIONS = [
    ActionTerm(a.name, a.category, a.takes_destination, a.requires_destination, a.countable, a.accepts,
               a.description)
    for a in ACTIONS.values()
]  # fmt: skip

SEED_CONCEPTS = [
    ConceptTerm("roof", "BuildingPart"),
    ConceptTerm("ceiling", "BuildingPart"),
    ConceptTerm("wall", "BuildingPart"),
    ConceptTerm("chimney", "BuildingPart"),
    ConceptTerm("sky", "CelestialThing"),
    ConceptTerm("moon", "CelestialThing"),
    ConceptTerm("sun", "CelestialThing"),
    ConceptTerm("cloud", "CelestialThing"),
    ConceptTerm("mars", "CelestialThing"),
    ConceptTerm("stars", "CelestialThing"),
]

_CONCEPT_SYNONYMS = {"roof": "rooftop", "sky": "heavens", "ceiling": "overhead", "stars": "star"}


SEED_SYNONYMS = [SynonymTerm(word, action=a.name) for a in ACTIONS.values() for word in a.synonyms] + [
    SynonymTerm(word, concept=concept) for concept, word in _CONCEPT_SYNONYMS.items()
]

SEED_KEYWORDS = [
    KeywordTerm(role.name, keyword, 2.0 if keyword == role.name or "_" in keyword else weight)
    for role in ROLES.values()
    for keyword, weight in role.keywords.items()
]


def seed_terms() -> Terms:
    """Return the terms the ontology starts with (paper sections 3.4-3.6)."""
    return Terms(
        actions=list(SEED_ACTIONS),
        classes=list(SEED_CLASSES),
        concepts=list(SEED_CONCEPTS),
        synonyms=list(SEED_SYNONYMS),
        keywords=list(SEED_KEYWORDS),
    )


def class_ancestry(classes: list[ClassTerm]) -> dict[str, tuple[str, ...]]:
    """Map each class to itself and its ancestors, nearest first."""
    parents = {c.name: c.parent for c in classes}
    out: dict[str, tuple[str, ...]] = {}
    for name in parents:
        chain, cur = [], name
        while cur and cur not in chain:
            chain.append(cur)
            cur = parents.get(cur)
        out[name] = tuple(chain)
    return out
