"""The History page's instructions as CSV or JSON, with the page's filters (?format=csv|json on /history/).

One row per instruction: who, when, which robots, how it ended and each stage's time. A CSV cell that starts
like a formula (= + - @) is prefixed with a quote, so a spreadsheet shows it instead of running it.
"""

import csv
import io
import json

from django.http import HttpResponse

MAX_ROWS = 10_000  # the newest this many: an export of everything is a database dump, not a page's
FIELDS = (
    "id", "received_at", "text", "user", "source", "cause", "robots", "type", "status", "outcome", "error",
    "interpreted_at", "dispatched_at", "first_command_at", "motion_started_at", "finished_at",
)  # fmt: skip
FORMATS = ("csv", "json")


def row(instruction) -> dict:
    """One instruction as the export says it (times in ISO 8601, robots by name)."""
    out = {}
    for field in FIELDS:
        value = getattr(instruction, field, None)
        if field == "user":
            value = instruction.user.username if instruction.user else None
        elif field == "robots":
            value = sorted(robot.name for robot in instruction.robots.all())
        elif hasattr(value, "isoformat"):
            value = value.isoformat()
        out[field] = value
    return out


def _cell(value) -> str:
    text = " ".join(value) if isinstance(value, list) else "" if value is None else str(value)
    return f"'{text}" if text[:1] in ("=", "+", "-", "@") else text


def response(rows, format: str) -> HttpResponse:
    """The rows (a queryset, filtered as the page filters it) as a download in this format."""
    rows = [row(instruction) for instruction in rows[:MAX_ROWS]]
    if format == "json":
        body = json.dumps(rows, ensure_ascii=False, indent=1)
        answer = HttpResponse(body, content_type="application/json")
    else:
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows({key: _cell(value) for key, value in item.items()} for item in rows)
        answer = HttpResponse(buffer.getvalue(), content_type="text/csv; charset=utf-8")
    answer["Content-Disposition"] = f'attachment; filename="history.{format}"'
    return answer
