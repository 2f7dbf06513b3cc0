"""Locations, schedules and instructions in the JSON API."""

import math
from dataclasses import replace
from datetime import time

from ninja import Query, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import Field, model_validator

from access.roles import api_auth
from audit import records as audit
from execution.instructions import submit
from execution.models import Instruction, TimeSlot
from fleetcore.interpretation import Interpretation
from interpreter import forms
from places.models import Location
from portal.api_types import Id, LocalTime, Name, NonBlank, Text, get_or_404, path_id
from portal.schemas import InstructionOut
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
    robot: Name
    start: LocalTime
    end: LocalTime
    goal: Name
    task: Text = Field("", max_length=50)  # TimeSlot.task's length: PostgreSQL refuses longer, SQLite not
    enabled: bool = True

    @model_validator(mode="after")
    def start_before_end(self):
        if self.start >= self.end:
            raise ValueError("end: must be after start")
        return self


class Destination(Schema):
    """Where click-to-move sends robots: a location by id, or a point on the map."""

    location: Id | None = None
    x: float | None = Field(None, allow_inf_nan=False, ge=-1e6, le=1e6)
    y: float | None = Field(None, allow_inf_nan=False, ge=-1e6, le=1e6)
    yaw: float | None = Field(None, allow_inf_nan=False, ge=-7, le=7, description="heading to end with, rad")

    @model_validator(mode="after")
    def one_place(self):
        has_point = self.x is not None and self.y is not None
        half_point = (self.x is None) != (self.y is None)
        if half_point or has_point == (self.location is not None):
            raise ValueError("destination: give a location id, or both x and y")
        return self


class InstructionIn(Schema):
    """Words for the interpreter (robot_ids: the robots selected on the page, for a text that names none), or
    (click-to-move) robot ids and a destination, which never become words."""

    text: NonBlank | None = Field(None, max_length=2000)
    robot_ids: list[Id] | None = Field(None, min_length=1, max_length=1000)
    destination: Destination | None = None
    answer_to: Id | None = Field(None, description="the instruction whose question this answers (it closes)")

    @model_validator(mode="after")
    def words_or_ids(self):
        if self.text is None and self.robot_ids is None:
            raise ValueError("text: give text, or robot_ids with a destination")
        if self.text is None and self.destination is None:
            raise ValueError("destination: robot_ids without text need a destination")
        if self.text is not None and self.destination is not None:
            raise ValueError("destination: goes with robot_ids and no text (click-to-move)")
        return self


@router.get("/locations", response=list[LocationOut], tags=["locations"])
def list_locations(request):
    return Location.objects.select_related("map")


@router.get("/schedules", response=list[TimeSlotOut], tags=["schedules"])
def list_schedules(request, robot: Name | None = None):
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


EDIT_SCHEDULES = api_auth("edit_schedules")


@router.post("/schedules", response={201: TimeSlotOut}, tags=["schedules"], auth=EDIT_SCHEDULES)
def create_slot(request, payload: TimeSlotIn):
    slot = TimeSlot.objects.create(**_slot_fields(payload))
    audit.record(request.user, "schedule.create", str(slot))
    return Status(201, slot)


@router.put("/schedules/{slot_id}", response=TimeSlotOut, tags=["schedules"], auth=EDIT_SCHEDULES)
def update_slot(request, payload: TimeSlotIn, slot_id: int = path_id()):
    slot = get_or_404(TimeSlot, "slot_id", pk=slot_id)
    for field, value in _slot_fields(payload).items():
        setattr(slot, field, value)
    slot.save()
    audit.record(request.user, "schedule.update", str(slot))
    return slot


@router.delete("/schedules/{slot_id}", response={204: None}, tags=["schedules"], auth=EDIT_SCHEDULES)
def delete_slot(request, slot_id: int = path_id()):
    slot = get_or_404(TimeSlot, "slot_id", pk=slot_id)
    audit.record(request.user, "schedule.delete", str(slot))
    slot.delete()
    return Status(204, None)


@router.get("/instructions", response=list[InstructionOut], tags=["instructions"])
def list_instructions(
    request,
    status: Instruction.Status | None = None,
    limit: int = Query(50, ge=1, le=500),
):
    rows = Instruction.objects.select_related("user")
    if status:
        rows = rows.filter(status=status)
    return rows[:limit]


@router.get("/instructions/{instruction_id}", response=InstructionOut, tags=["instructions"])
def instruction_detail(request, instruction_id: int = path_id()):
    return get_or_404(Instruction.objects.select_related("user"), "instruction_id", pk=instruction_id)


@router.post(
    "/instructions", response={201: InstructionOut}, tags=["instructions"], auth=api_auth("instruct")
)
def create_instruction(request, payload: InstructionIn):
    """Give an instruction in words, or send robots (by id) to a place: click-to-move, no words involved."""
    if payload.text is None:
        text, parse = _move_by_ids(payload.robot_ids, payload.destination)
        return Status(201, submit(text, request.user, source="api", parse=parse))
    answer_to = None
    if payload.answer_to is not None:
        answer_to = get_or_404(
            Instruction, "answer_to", pk=payload.answer_to, status=Instruction.Status.NEEDS_USER
        )
    return Status(
        201,
        submit(payload.text, request.user, source="api", answer_to=answer_to, robot_ids=payload.robot_ids),
    )


def _move_by_ids(robot_ids: list[int], destination: Destination) -> tuple[str, Interpretation]:
    """The parse of "move these robots there", built from ids: a robot's name is never read as words."""
    robots = list(Robot.objects.filter(pk__in=robot_ids))
    missing = sorted(set(robot_ids) - {robot.pk for robot in robots})
    if missing:
        raise HttpError(422, f"robot_ids: no robot with id {', '.join(map(str, missing))}")
    if destination.location is not None:
        place = get_or_404(Location, "destination.location", pk=destination.location)
        goal = {"name": place.name, "x": place.x, "y": place.y}
        where = place.name
    else:
        goal = {"name": "", "x": destination.x, "y": destination.y}
        where = f"({destination.x:g}, {destination.y:g})"
    if destination.yaw is not None:
        goal["yaw"] = destination.yaw
        where += f" facing {math.degrees(destination.yaw):.0f}°"
    text = f"move robots {', '.join(map(str, robot_ids))} to {where}"
    understood = Interpretation.for_robots(
        [robot.name for robot in robots], "move", "click-to-move: robots given by id", goal
    )
    return text, replace(understood, read_back=tuple(map(forms.read_back, understood.steps)))
