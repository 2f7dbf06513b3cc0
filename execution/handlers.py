"""The executor's handlers, one per action of the registry (fleetcore/actions.py names each by dotted path).

A handler takes the running Session and one checked Step, drives the robot through the session's link, and
returns a few words on what was done; it raises StepFailed (with a reason for a person) or lets Interrupted
(a stop or a preemption) pass through.
"""

from __future__ import annotations

import math
import time

import live
from execution import traffic
from execution.steps import Blocked, Session, drive, follow_goal, travel_time
from fleetcore import motion
from fleetcore.states import Event
from fleetcore.steps import Destination, Step, parse_task
from robots.models import Robot

REROUTES, BACK_OFF_S = 2, 1.0
DOCK_LIMIT_S = 120.0


def go_to(session: Session, step: Step) -> str:
    """Move (or navigate) to the step's destination, then do its task there if it has one."""
    note = _travel(session, step.destination, step.factor) if step.destination is not None else ""
    return task(session, step) if step.task else f"arrived at {_where(step)}{note}"


def task(session: Session, step: Step) -> str:
    """rotate(n) on the spot or clean a small square, where the robot is (after go_to, at the destination)."""
    if step.destination is not None and step.action not in ("move", "navigate"):
        _travel(session, step.destination, step.factor)
    name, count = parse_task(step.task or step.action)
    where = _where(step)
    Robot.objects.transition(
        session.robot.pk, Event.WORK, f"{name} at {where}", session.execution.instruction_id
    )
    pose = session.pose()
    limits = session.link.limits()
    controller = motion.task_controller(step.task or step.action, pose, limits, step.factor)
    if name == "rotate":
        limit = travel_time(0.0, 2 * math.pi * count, limits, step.factor)
    else:
        limit = travel_time(
            motion.CLEAN_SIZE * (motion.CLEAN_LANES + 2), 2 * math.pi * 3, limits, step.factor
        )
    drive(session, controller, limit)
    return f"{step.task or name} done at {where}"


def dock(session: Session, step: Step) -> str:
    """Dock: the robot's own docking action where it has one, else drive to its start pose ("home")."""
    robot = session.robot
    Robot.objects.transition(robot.pk, Event.MOVE, "docking", session.execution.instruction_id)
    if session.link.can_dock:
        session.check()
        goal = session.link.dock()
        session.mark_commanded()
        follow_goal(session, goal, DOCK_LIMIT_S, "docking")
        return "docked"
    x0, y0, _ = robot.start_pose or (0.0, 0.0, 0.0)
    _travel(session, Destination("home", x0, y0), step.factor)
    return "back at its start pose (no docking action bound)"


def report_position(session: Session, step: Step) -> str:
    x, y, yaw = session.pose()
    return f"{session.robot.name} is at ({x:.2f}, {y:.2f}), heading {math.degrees(yaw):.0f}°"


def _where(step: Step) -> str:
    return step.destination.name if step.destination else "its place"


def _travel(session: Session, destination: Destination, factor: float) -> str:
    """Go there; "" or, when the spot was taken on arrival, where the robot stopped instead (traffic)."""
    x, y, name = destination.x, destination.y, destination.name
    Robot.objects.transition(
        session.robot.pk, Event.MOVE, f"moving to {name}", session.execution.instruction_id
    )
    live.goal(session.robot, name, x, y)  # the map draws the goal until the robot is done with it
    limits = session.link.limits()
    try:
        if session.link.nav_kind:
            nav_speed = min(limits.linear, 0.22) * 0.5  # nav stacks drive at their own (often slow) speed
            return traffic.travel(
                session, (x, y), limits, nav_speed / limits.linear, nav=True
            )  # goal by goal
        return drive_route(session, (x, y), limits, factor)
    finally:
        live.goal(session.robot, None, None, None)


def drive_route(session: Session, goal: tuple[float, float], limits: motion.Limits, factor: float) -> str:
    """Drive a route leg by leg with the Figure 7 controller: loose at the corners, within tolerance at the goal.

    Blocked on the way (a robot that parked there after the plan was made), the robot backs off a little and
    plans again from where it is, with the other robots' live poses, up to REROUTES times.
    """
    for attempt in range(REROUTES + 1):
        try:
            return traffic.travel(session, goal, limits, factor)  # reserved, then claimed stretch by stretch
        except Blocked:
            if attempt == REROUTES:
                raise
            back_off(session, limits)


def back_off(session: Session, limits: motion.Limits) -> None:
    """Reverse slowly for a moment, to leave room to turn."""
    until = time.monotonic() + BACK_OFF_S
    while time.monotonic() < until:
        session.send(-0.25 * limits.linear, 0.0)
        session.pose()
    session.link.halt()
