"""Input types the API shares: what any database takes, refused with a 422 naming the field otherwise.

SQLite and PostgreSQL disagree at the edges: PostgreSQL refuses NUL characters in text, SQLite integers above
2**63 - 1 and time-zone-aware times. Checking here, once, gives the same clear answer on both.
"""

from datetime import time
from typing import Annotated

from ninja import Path
from ninja.errors import HttpError
from pydantic import AfterValidator, Field

MAX_ID = 2**63 - 1  # the largest primary key either database stores


def _no_nul(value: str) -> str:
    if "\x00" in value:
        raise ValueError("must not contain NUL characters")
    return value


def _naive(value: time) -> time:
    if value.tzinfo is not None:
        raise ValueError("give a local time without a time zone (schedules run in the portal's TIME_ZONE)")
    return value


def _not_blank(value: str) -> str:
    if not value.strip():
        raise ValueError("must not be blank")
    return value.strip()


Text = Annotated[str, AfterValidator(_no_nul)]
Name = Annotated[str, Field(max_length=255), AfterValidator(_no_nul)]
NonBlank = Annotated[str, AfterValidator(_no_nul), AfterValidator(_not_blank)]
Id = Annotated[int, Field(ge=1, le=MAX_ID)]
LocalTime = Annotated[time, AfterValidator(_naive)]


def path_id():
    """A primary key in the URL, within what the database stores."""
    return Path(..., ge=1, le=MAX_ID)


def get_or_404(queryset, field: str, **lookup):
    """The row, or a 404 whose detail names the field that found nothing."""
    rows = queryset.objects.all() if hasattr(queryset, "objects") else queryset
    row = rows.filter(**lookup).first()
    if row is None:
        value = next(iter(lookup.values()), "")
        raise HttpError(404, f"{field}: nothing matches {value!r}")
    return row


def ids_from_text(values) -> list[int]:
    """Robot ids from form text ("3", " 7 "): ASCII digits within MAX_ID; anything else is left out."""
    found = []
    for value in values:
        value = str(value).strip()
        if value.isascii() and value.isdigit() and 1 <= int(value) <= MAX_ID:
            found.append(int(value))
    return found
