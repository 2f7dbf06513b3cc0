"""Submitting an instruction: store it, interpret it, and hand it to execution."""

from django.utils import timezone

from fleet import audit
from fleet.models import Instruction


def submit(text: str, user, source: str = "console") -> Instruction:
    """Receive, interpret and (when understood) dispatch one instruction."""
    instruction = Instruction.objects.create(text=text, user=user, source=source)
    audit.record(user, "instruct", text[:255], instruction=instruction.pk, source=source)
    from interpreter.service import interpret

    result = interpret(text)
    instruction.parse = result
    instruction.type = result["type"]
    instruction.interpreted_at = timezone.now()
    if result["needs_user"]:
        instruction.status = Instruction.Status.NEEDS_USER
        instruction.outcome = result.get("question") or result.get("reason", "")
    else:
        instruction.status = Instruction.Status.QUEUED
    instruction.save()
    return instruction
