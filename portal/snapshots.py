"""What a new subscriber sees first (the snapshot), and the rows the pages render: the same data, one place."""

import time

from django.db.models import prefetch_related_objects
from django.utils import timezone

from access.models import ControlLease
from alerts import service
from alerts.models import Alert
from execution import queues, traffic_state
from execution.models import Execution, Instruction
from robots.models import Robot
from robots.poses import kept_poses


def _robot_row(robot, holders: dict, current: dict, goals: dict, cached: dict) -> dict:
    """One robot as the browser draws it."""
    return {
        "id": robot.pk,
        "name": robot.name,
        "model": robot.model,
        "drive": robot.drive,
        "state": robot.state,
        "link_status": robot.link_status,
        "last_seen": robot.last_seen.isoformat() if robot.last_seen else None,
        "footprint": robot.footprint,
        "max_linear": robot.max_linear,
        "max_angular": robot.max_angular,
        "start_pose": robot.start_pose,
        "holder": holders.get(robot.pk, (None, None))[0],
        "held_until": holders.get(robot.pk, (None, None))[1],
        "stop_hold": robot.hold_words,  # "held by a stop (admin, 10:43:44)": nothing automatic moves it
        "instruction": current.get(robot.pk),
        "goal": goals.get(robot.pk),
        "pose": cached.get(robot.pk),
    }


def robot_rows(robots) -> list[dict]:
    """The robots with their holders, current instructions, goals and last poses, in few queries."""
    robots = list(robots)
    prefetch_related_objects(robots, "held_by")  # the stops' holders, in one query
    ids = [robot.pk for robot in robots]
    leases = ControlLease.objects.filter(robot_id__in=ids, expires_at__gt=timezone.now()).values_list(
        "robot_id", "user__username", "expires_at"
    )
    holders = {pk: (name, until.isoformat()) for pk, name, until in leases}
    current, goals = Execution.objects.current_work(ids)
    try:
        cached = kept_poses(ids)
    except Exception:  # a missing cache only costs the first tick of poses
        cached = {}
    rows = [_robot_row(robot, holders, current, goals, cached) for robot in robots]
    _add_routes(rows, {robot.pk: robot.name for robot in robots})
    return rows


def _add_routes(rows: list[dict], names: dict) -> None:
    """Each robot's reserved route (what is left of it) and whom it waits for, as the map draws them."""
    try:
        found = traffic_state.routes(names)
    except Exception:  # Redis away: the next live.path says it
        return
    blockers = {entry["waiting_for"] for entry in found.values()} - set(names) - {None}
    names = {**names, **dict(Robot.objects.filter(pk__in=blockers).values_list("pk", "name"))}
    for row in rows:
        entry = found.get(row["id"])
        if entry is None:
            continue
        path, pose = entry["path"], row["pose"]
        if pose and path:  # drop what is behind the robot: from the point nearest to it on
            nearest = min(
                range(len(path)), key=lambda i: (path[i][0] - pose["x"]) ** 2 + (path[i][1] - pose["y"]) ** 2
            )
            path = path[nearest:]
        blocker = entry["waiting_for"]
        row["route"] = path
        row["waiting_for"] = names.get(blocker) or (f"#{blocker}" if blocker is not None else None)


def _instruction_row(instruction) -> dict:
    return {
        "id": instruction.pk,
        "text": instruction.text,
        "status": instruction.status,
        "type": instruction.type,
        "outcome": instruction.outcome,
        "user": instruction.user.username if instruction.user else None,
    }


def fleet_snapshot() -> dict:
    """What a new dashboard subscriber sees first: every robot (lease, goal, pose) and recent instructions."""
    recent = Instruction.objects.select_related("user")[:20]
    return {
        "type": "snapshot",
        "server_time": time.time(),  # the clock the poses' "t" is on: the browser ages poses by it
        "robots": robot_rows(Robot.objects.all()),
        "instructions": [_instruction_row(instruction) for instruction in recent],
        "queues": queues.all_queues(),  # the task list: what each busy robot runs and what waits
    }


def robot_snapshot(robot) -> dict:
    """What a new robot-page subscriber sees first: the robot and its last state transitions."""
    transitions = robot.transitions.all()[:20]
    return {
        "type": "snapshot",
        "server_time": time.time(),
        "robots": robot_rows([robot]),
        "queue": queues.robot_queue(robot),
        "transitions": [
            {
                "from_state": record.from_state,
                "to_state": record.to_state,
                "at": record.at.isoformat(),
                "reason": record.reason,
                "instruction": record.instruction_id,
            }
            for record in transitions
        ],
    }


def alerts_snapshot(limit: int = 20) -> dict:
    """What every page's alert badge starts from: the open count and the newest open alerts."""
    rows = Alert.objects.open().select_related("robot", "acknowledged_by", "resolved_by")[:limit]
    return {
        "type": "alerts.snapshot",
        "open_count": service.open_count(),
        "alerts": [service.as_dict(alert) for alert in rows],
    }
