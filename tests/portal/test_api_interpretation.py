"""The interpretation in the OpenAPI document: generated from the dataclass and the step contract's wire form
(portal/interpretation_schema.py), so its keys are exactly those `Interpretation.to_dict` writes, and every answer
that carries one (the interpreter's, an instruction's parse, a lesson's) validates against it."""

from dataclasses import dataclass, field

import jsonschema_rs
import pytest

from execution.models import Instruction
from fleetcore.interpretation import Interpretation
from fleetcore.steps import StepWire
from interpreter import service
from portal.interpretation_schema import schema_of
from portal.schemas import InstructionOut

# One text of each kind the interpreter tells apart (fleet: turtlebot and husky; places A and B).
TEXTS = {
    "move husky to A": "I",
    "shift husky to B and clean": "II",  # shift: a synonym of move
    "move husky to the roof": "III",  # a place the map does not have: a question
    "scoot husky to A": "V",  # a verb nobody taught
    "move husky forward 2 metres": "I",  # an amount
    "every robot except husky go to A": "II",  # robots as a subject object
    "cancel #12": "I",  # an instruction's number
}


@pytest.fixture
def openapi(client_for, viewer):
    """The OpenAPI document as a viewer fetches it."""
    reply = client_for(viewer).get("/api/openapi.json")
    assert reply.status_code == 200
    return reply.json()


@pytest.fixture
def interpretations(fleet, seeded_words):
    """Each text of TEXTS as the interpreter reads it, its type checked."""
    read = {text: service.interpret(text) for text in TEXTS}
    assert {text: understood.type for text, understood in read.items()} == TEXTS
    return read


def _validator(openapi: dict, ref: str):
    """A validator of one response schema of the document, its references resolved within the document."""
    return jsonschema_rs.Draft202012Validator({"$ref": ref, "components": openapi["components"]})


def _response_ref(openapi: dict, path: str, status: str = "200") -> str:
    return openapi["paths"][path]["post"]["responses"][status]["content"]["application/json"]["schema"][
        "$ref"
    ]


def test_the_schema_lists_exactly_the_keys_an_interpretation_has(openapi, interpretations):
    schema = openapi["components"]["schemas"]["Interpretation"]
    for text, understood in interpretations.items():
        keys = set(understood.to_dict())
        assert set(schema["properties"]) == keys, text
        assert set(schema["required"]) == keys, text
    assert schema["properties"]["type"]["enum"] == ["I", "II", "III", "IV", "V"]
    steps = openapi["components"]["schemas"]["StepWire"]["properties"]
    assert set(steps) == set(StepWire.__annotations__)
    written = {key for understood in interpretations.values() for step in understood.steps for key in step}
    assert written <= set(steps) and {"amount", "destination", "instruction"} <= written


def test_a_key_added_to_the_dataclass_is_in_its_schema():
    @dataclass(frozen=True)
    class Wider(Interpretation):
        mood: str = field(default="calm", metadata={"doc": "how it was said", "wire": True})

    keys = set(schema_of(Wider).model_json_schema()["properties"])
    assert keys == set(Wider("I").to_dict()) == set(Interpretation("I").to_dict()) | {"mood"}


def test_the_interpreters_answers_validate_against_the_schema(client_for, viewer, openapi, interpretations):
    ref = _response_ref(openapi, "/api/interpreter/interpret")
    assert ref == "#/components/schemas/Interpretation"
    validator = _validator(openapi, ref)
    api = client_for(viewer)
    for text, understood in interpretations.items():
        reply = api.post("/api/interpreter/interpret", {"text": text}, content_type="application/json")
        assert reply.status_code == 200, reply.content
        validator.validate(reply.json())
        assert reply.json() == understood.to_dict(), text  # nothing added, nothing lost on the way


def test_an_instructions_parse_is_the_interpretation(client_for, operator, openapi, interpretations):
    instruction_schema = openapi["components"]["schemas"]["InstructionOut"]
    parse = instruction_schema["properties"]["parse"]
    assert {"$ref": "#/components/schemas/Interpretation"} in parse["anyOf"]
    validator = _validator(openapi, _response_ref(openapi, "/api/instructions", "201"))
    reply = client_for(operator).post(
        "/api/instructions", {"text": "move husky to the roof"}, content_type="application/json"
    )
    assert reply.status_code == 201, reply.content
    validator.validate(reply.json())
    assert reply.json()["parse"]["question"] and reply.json()["parse"]["needs_user"]
    unread = Instruction.objects.create(text="not read yet", user=operator)
    assert InstructionOut.of(unread)["parse"] is None  # what the console's socket sends, too
    validator.validate(client_for(operator).get(f"/api/instructions/{unread.pk}").json())


def test_a_lessons_instruction_is_the_interpretation(client_for, fleet_admin, openapi, interpretations):
    validator = _validator(openapi, _response_ref(openapi, "/api/interpreter/teach"))
    question = Instruction.objects.create(text="scoot husky to A", user=fleet_admin, status="needs_user")
    body = {"answer": "scoot means move", "instruction_id": question.pk}
    reply = client_for(fleet_admin).post("/api/interpreter/teach", body, content_type="application/json")
    assert reply.status_code == 200, reply.content
    validator.validate(reply.json())
    assert reply.json()["instruction"]["type"] == "II"
    refused = client_for(fleet_admin).post(
        "/api/interpreter/teach", {"answer": "gibberish"}, content_type="application/json"
    )
    validator.validate(refused.json())
    assert set(refused.json()) == {"ok", "message", "examples"}  # absent keys stay absent, never null
