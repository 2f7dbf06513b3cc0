"""Schemas shared by the JSON API and the page sockets: one shape per resource, wherever it travels."""

from datetime import datetime

from ninja import Field, Schema
from pydantic import field_validator

from fleetcore.interpretation import Interpretation
from portal.interpretation_schema import InterpretationOut


class InstructionOut(Schema):
    id: int | None = Field(None, description="None for a stop the database could not record (it was done)")
    text: str
    user: str | None = Field(None, alias="user.username")
    source: str = Field("console", description="console, api, cli; the system's: schedule, traffic")
    cause: str = Field(
        "", description="why the system sent it (no user): make way for husky, instruction #14 by admin"
    )
    type: str
    status: str
    parse: InterpretationOut | None = Field(description="how it was read; null before it was")
    outcome: str
    error: str
    received_at: datetime
    interpreted_at: datetime | None
    dispatched_at: datetime | None
    first_command_at: datetime | None
    motion_started_at: datetime | None
    finished_at: datetime | None

    @field_validator("parse", mode="before")
    @classmethod
    def _read(cls, stored):
        """The stored parse in its current shape (Interpretation.from_dict); an empty one (not read yet): null."""
        return Interpretation.from_dict(stored).to_dict() if stored else None

    @classmethod
    def of(cls, instruction) -> dict:
        """The instruction as JSON-ready data (the socket sends what the API answers)."""
        return cls.from_orm(instruction).model_dump(mode="json", by_alias=False)
