"""What the page does, in the JSON API: cancel an instruction, a robot's queue (and its order), stop, control
leases. Each call goes through the same domain function as the page and the console, so the same role rules
hold (a viewer is refused each of the calls that change something)."""

from datetime import datetime
from typing import Literal

from ninja import Router, Schema
from ninja.errors import HttpError
from pydantic import Field

from access import leases
from access.leases import ControlRefused
from access.roles import api_auth
from execution import queues, tasklist
from execution.instructions import submit
from execution.models import Instruction
from fleetcore.interpretation import EVERY, Interpretation
from portal.api_types import Name, get_or_404, path_id
from portal.schemas import InstructionOut
from robots.models import Robot

router = Router()


class QueueEntryOut(Schema):
    """One instruction in a robot's queue (live.QueueEntry: the socket's robot.queue carries the same)."""

    instruction: int
    text: str
    user: str | None
    status: str
    position: int = Field(description="0: running now; 1..: the order the waiting ones will run in")
    step: int | None = Field(description='the step it is at: "step 2 of 3" is step 2, steps 3')
    steps: int
    doing: str = Field(description="that step in words")
    goal: dict | None = Field(description="a move's goal on the map: {name, x, y}; null for other steps")
    distance_left: float | None = Field(description="m, straight line from the last pose to a move's goal")
    speed: float | None = Field(description="m/s, the step's speed word on the robot's limit")
    eta_s: float | None = Field(description="s, distance_left / speed")


class QueueOut(Schema):
    """A robot's task list (live.RobotQueue, the socket's robot.queue, without its type)."""

    robot: str
    id: int
    running: QueueEntryOut | None
    queued: list[QueueEntryOut]


class MoveIn(Schema):
    direction: Literal["up", "down"]


class StopIn(Schema):
    robots: list[Name] | None = Field(
        None, max_length=1000, description="the robots to stop by name; null or absent: every robot"
    )


class LeaseOut(Schema):
    robot: str
    holder: str | None
    expires_at: datetime | None


def _refused(exc: Exception, field: str, ability: str = "instruct"):
    """403 for a refusal, in its words and naming the ability (access.roles), 409 for a conflict, naming the
    field that points at it."""
    if isinstance(exc, ControlRefused):
        return HttpError(403, f"{exc} ({ability})")
    return HttpError(409, f"{field}: {exc}")


@router.post(
    "/instructions/{instruction_id}/cancel",
    response=InstructionOut,
    tags=["instructions"],
    auth=api_auth("instruct"),
)
def cancel_instruction(request, instruction_id: int = path_id()):
    """Cancel one instruction: its waiting work dropped, a running one stopped with its robot brought to rest;
    settled as cancelled by the caller (403: the caller may not; 409: it is already over)."""
    instruction = get_or_404(Instruction, "instruction_id", pk=instruction_id)
    try:
        return tasklist.cancel_instruction(instruction, request.user, source="api")
    except (ControlRefused, tasklist.NothingToCancel) as exc:
        raise _refused(exc, "instruction_id") from exc


@router.get("/robots/{name}/queue", response=QueueOut, tags=["robots"])
def robot_queue(request, name: Name):
    """What the robot runs now (step, distance left, ETA) and what waits behind it, in the order it will run."""
    return queues.robot_queue(get_or_404(Robot, "name", name=name))


@router.post(
    "/robots/{name}/queue/{instruction_id}/move",
    response=QueueOut,
    tags=["robots"],
    auth=api_auth("instruct"),
)
def move_in_queue(request, name: Name, payload: MoveIn, instruction_id: int = path_id()):
    """Move a waiting instruction one place up or down the robot's queue (409: it does not wait there)."""
    robot = get_or_404(Robot, "name", name=name)
    try:
        queues.move_in_queue(instruction_id, robot, request.user, up=payload.direction == "up")
    except (ControlRefused, queues.NotQueued) as exc:
        raise _refused(exc, "instruction_id") from exc
    return queues.robot_queue(robot)


@router.post("/stop", response=InstructionOut, tags=["robots"], auth=api_auth("control"))
def stop(request, payload: StopIn):
    """Stop some robots, or every robot: the typed stop's path (zeros first, then flags, the queued work
    cancelled, the robots held, audited); the answer is the stop as an instruction, its outcome per robot."""
    names = sorted(set(payload.robots or []))
    missing = sorted(set(names) - set(Robot.objects.filter(name__in=names).values_list("name", flat=True)))
    if missing:
        raise HttpError(422, f"robots: no robot named {', '.join(map(repr, missing))}")
    parse = Interpretation.for_robots(
        names or EVERY, "stop", "a stop through the API", read_back=[f"stop {', '.join(names) or 'all'}"]
    )
    text = f"stop {', '.join(names)}" if names else "stop every robot"  # stored, never read as words
    return submit(text, request.user, source="api", parse=parse)


def _lease_out(robot: Robot) -> dict:
    lease = leases.active([robot]).first()
    return {
        "robot": robot.name,
        "holder": lease.user.username if lease else None,
        "expires_at": lease.expires_at if lease else None,
    }


@router.post("/robots/{name}/lease", response=LeaseOut, tags=["robots"], auth=api_auth("control"))
def take_lease(request, name: Name):
    """Take (or renew) control of a robot; an admin takes it over from anyone (403 otherwise while held)."""
    robot = get_or_404(Robot, "name", name=name)
    try:
        leases.take(request.user, robot)
    except ControlRefused as exc:
        raise _refused(exc, "name", "control") from exc
    return _lease_out(robot)


@router.delete("/robots/{name}/lease", response=LeaseOut, tags=["robots"], auth=api_auth("control"))
def release_lease(request, name: Name):
    """Give control of a robot back (the holder, or an admin)."""
    robot = get_or_404(Robot, "name", name=name)
    try:
        leases.release(request.user, robot)
    except ControlRefused as exc:
        raise _refused(exc, "name", "control") from exc
    return _lease_out(robot)
