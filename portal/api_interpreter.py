"""JSON API of the interpreter (mounted by portal.api under /api/interpreter/)."""

from ninja import Router, Schema

from interpreter import service

router = Router(tags=["interpreter"])


class InterpretIn(Schema):
    text: str


class TeachIn(Schema):
    answer: str
    instruction_id: int | None = None


@router.post("/interpret")
def interpret(request, body: InterpretIn):
    """Interpret an instruction without running it."""
    return service.interpret(body.text)


@router.post("/teach")
def teach(request, body: TeachIn):
    """Teach the ontology from a person's answer to a question."""
    return service.teach(body.answer, request.user, body.instruction_id)
