"""JSON API of the interpreter (mounted by portal.api under /api/interpreter/).

Who may teach (access.roles.ABILITIES): teaching changes what words mean for everyone, so
- operators and admins ("teach") may add a word the interpreter does not know yet (a synonym, a thing that is not
  a place, a named point). A word that already means something is refused ("say 'forget X' first"), so adding
  can never change what a working instruction does; and they may forget a word people taught: the undo of a lesson.
- only admins ("edit_vocabulary") may forget a word of the seeded vocabulary: "forget halt" would leave every
  operator's stop word meaning nothing (and then free to be taught as "move").
Every lesson is stored (interpreter.Lesson: who, when, what) and audited ("ontology.teach").
"""

from ninja import Router, Schema
from ninja.errors import HttpError
from pydantic import Field

from access.roles import api_auth, may, refusal
from interpreter import service
from interpreter.lessons import parse_answer
from interpreter.models import Lesson
from portal.api_types import Id, Text
from portal.interpretation_schema import InterpretationOut

router = Router(tags=["interpreter"])


class InterpretIn(Schema):
    text: Text = Field(max_length=2000)


class TeachIn(Schema):
    answer: Text = Field(max_length=1000)
    instruction_id: Id | None = None


class TeachOut(Schema):
    """What a lesson taught (interpreter.service.teach); when refused, ok is false with the message and examples."""

    ok: bool
    message: str
    examples: list[str] = Field(None, description="answers that would do (when refused)")
    kind: str = Field(None, description="synonym, not_a_place, location, forget")
    word: str = Field(None, description="the word taught")
    meaning: str = Field(None, description="what it means now")
    lesson_id: int = Field(None, description="the stored lesson")
    ontology_version: int = Field(None, description="the ontology's version after the lesson")
    instruction: InterpretationOut = Field(
        None, description="the instruction answered (instruction_id), read again with what was taught"
    )


@router.post("/interpret", response=InterpretationOut)
def interpret(request, body: InterpretIn):
    """Interpret an instruction without running it."""
    return service.interpret(body.text).to_dict()


@router.post("/teach", response=TeachOut, auth=api_auth("teach"), exclude_unset=True)
def teach(request, body: TeachIn):
    """Teach the ontology from a person's answer to a question (forgetting a seeded word: admins only)."""
    _refuse_forgetting_seeded(request.user, body.answer)
    return service.teach(body.answer, request.user, body.instruction_id)


def _refuse_forgetting_seeded(user, answer: str) -> None:
    """An operator's "forget X" undoes a lesson; forgetting a word nobody taught needs edit_vocabulary."""
    try:
        parsed = parse_answer(answer)
    except ValueError:
        return  # not understood: service.teach says so, with examples
    if parsed.kind != "forget" or may(user, "edit_vocabulary"):
        return
    taught = Lesson.objects.filter(word=parsed.word).exclude(kind=Lesson.Kind.FORGET).exists()
    if not taught:
        raise HttpError(
            403, f"answer: '{parsed.word}' was not taught by a person; {refusal(user, 'edit_vocabulary')}"
        )
