"""The owlready2 ontology: built from the terms, read back, exported and imported."""

import owlready2 as owl
import pytest

from interpreter import ontology
from interpreter.lexicon import Lexicon
from interpreter.terms import seed_terms


def signature(lexicon: Lexicon) -> tuple:
    """What a lexicon knows, comparable: its actions, its action and concept phrases, its concepts."""
    return (
        sorted(lexicon.actions.values(), key=lambda s: s.name),
        sorted((k, v.value, v.synonym) for k, v in lexicon.action_phrases.items()),
        sorted((k, v.value, v.synonym) for k, v in lexicon.concept_phrases.items()),
        sorted(lexicon.concepts.items()),
    )


def test_snapshot_through_owl_equals_the_plain_lexicon():
    terms = seed_terms()
    assert signature(ontology.snapshot(terms)) == signature(Lexicon(terms))


def test_owl_has_sameas_synonyms_and_allvaluesfrom_restrictions():
    onto = ontology.build(seed_terms())
    try:
        shift = onto.search_one(iri=ontology.NS + "word_shift")
        assert onto.search_one(iri=ontology.NS + "action_move") in shift.equivalent_to
        restrictions = [r for r in onto.Move.is_a if isinstance(r, owl.Restriction)]
        assert any(r.type == owl.ONLY and r.value is onto.Location for r in restrictions)
        assert issubclass(onto.Room, onto.Location) and not issubclass(onto.BuildingPart, onto.Location)
        assert onto.default_world is not owl.default_world
    finally:
        onto.world.close()


def test_export_import_round_trip():
    terms = seed_terms()
    terms.robot_models = [("turtlebot3_burger", "wheeled"), ("spot", "legged")]
    data = ontology.export_rdfxml(terms)
    assert b"owl:allValuesFrom" in data and b"owl:sameAs" in data
    assert ontology.import_rdfxml(data).sorted() == terms.sorted()


@pytest.mark.parametrize(
    "data",
    [
        b"not xml at all",
        b"<?xml version='1.0'?><rdf:RDF xmlns:rdf='http://www.w3.org/1999/02/22-rdf-syntax-ns#'/>",
    ],
)
def test_import_of_garbage_is_a_clear_error(data):
    with pytest.raises(ValueError, match="ontology"):
        ontology.import_rdfxml(data)
