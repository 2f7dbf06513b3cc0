"""Schemas shared by the JSON API and the page sockets: one shape per resource, wherever it travels."""

from datetime import datetime

from ninja import Field, Schema


class InstructionOut(Schema):
    id: int
    text: str
    user: str | None = Field(None, alias="user.username")
    type: str
    status: str
    parse: dict
    outcome: str
    error: str
    received_at: datetime
    interpreted_at: datetime | None
    dispatched_at: datetime | None
    first_command_at: datetime | None
    motion_started_at: datetime | None
    finished_at: datetime | None

    @classmethod
    def of(cls, instruction) -> dict:
        """The instruction as JSON-ready data (the socket sends what the API answers)."""
        return cls.from_orm(instruction).model_dump(mode="json", by_alias=False)
