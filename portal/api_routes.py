"""Locations, schedules and instructions in the JSON API."""

from datetime import datetime, time

from django.shortcuts import get_object_or_404
from ninja import Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import Field, model_validator

from access.roles import CONTROL_PERM, SCHEDULE_PERM, require_perm
from audit import records as audit
from execution.models import Instruction, TimeSlot
from places.models import Location
from robots.models import Robot

router = Router()


class LocationOut(Schema):
    id: int
    name: str
    x: float
    y: float
    yaw: float
    kind: str
    map: str = Field(alias="map.name")


class TimeSlotOut(Schema):
    id: int
    robot: str = Field(alias="robot.name")
    start: time
    end: time
    goal: str = Field(alias="goal.name")
    task: str
    enabled: bool


class TimeSlotIn(Schema):
    robot: str
    start: time
    end: time
    goal: str
    task: str = ""
    enabled: bool = True

    @model_validator(mode="after")
    def start_before_end(self):
        if self.start >= self.end:
            raise ValueError("end: must be after start")
        return self


class InstructionIn(Schema):
    text: str = Field(min_length=1, max_length=2000)
    robot_ids: list[int] | None = Field(
        None, max_length=1000, description="robots selected on the page: a text naming no robot goes to them"
    )


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


@router.get("/locations", response=list[LocationOut], tags=["locations"])
def list_locations(request):
    return Location.objects.select_related("map")


@router.get("/schedules", response=list[TimeSlotOut], tags=["schedules"])
def list_schedules(request, robot: str | None = None):
    slots = TimeSlot.objects.select_related("robot", "goal")
    return slots.filter(robot__name=robot) if robot else slots


def _slot_fields(payload: TimeSlotIn) -> dict:
    robot = Robot.objects.filter(name=payload.robot).first()
    if robot is None:
        raise HttpError(422, f"robot: no robot named {payload.robot!r}")
    goal = Location.objects.filter(name=payload.goal).first()
    if goal is None:
        raise HttpError(422, f"goal: no location named {payload.goal!r}")
    return {"robot": robot, "goal": goal, **payload.dict(include={"start", "end", "task", "enabled"})}


@router.post("/schedules", response={201: TimeSlotOut}, tags=["schedules"])
def create_slot(request, payload: TimeSlotIn):
    require_perm(request, SCHEDULE_PERM)
    slot = TimeSlot.objects.create(**_slot_fields(payload))
    audit.record(request.user, "schedule.create", str(slot))
    return Status(201, slot)


@router.put("/schedules/{slot_id}", response=TimeSlotOut, tags=["schedules"])
def update_slot(request, slot_id: int, payload: TimeSlotIn):
    require_perm(request, SCHEDULE_PERM)
    slot = get_object_or_404(TimeSlot, pk=slot_id)
    for field, value in _slot_fields(payload).items():
        setattr(slot, field, value)
    slot.save()
    audit.record(request.user, "schedule.update", str(slot))
    return slot


@router.delete("/schedules/{slot_id}", response={204: None}, tags=["schedules"])
def delete_slot(request, slot_id: int):
    require_perm(request, SCHEDULE_PERM)
    slot = get_object_or_404(TimeSlot, pk=slot_id)
    audit.record(request.user, "schedule.delete", str(slot))
    slot.delete()
    return Status(204, None)


@router.get("/instructions", response=list[InstructionOut], tags=["instructions"])
def list_instructions(request, status: str | None = None, limit: int = 50):
    rows = Instruction.objects.select_related("user")
    if status:
        rows = rows.filter(status=status)
    return rows[: max(1, min(limit, 500))]


@router.get("/instructions/{instruction_id}", response=InstructionOut, tags=["instructions"])
def instruction_detail(request, instruction_id: int):
    return get_object_or_404(Instruction.objects.select_related("user"), pk=instruction_id)


@router.post("/instructions", response={201: InstructionOut}, tags=["instructions"])
def create_instruction(request, payload: InstructionIn):
    require_perm(request, CONTROL_PERM)
    from execution.instructions import submit

    return Status(201, submit(payload.text, request.user, source="api", robot_ids=payload.robot_ids))
