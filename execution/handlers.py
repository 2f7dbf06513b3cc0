"""The executor's handlers, one per action of the registry (fleetcore/actions.py names each; HANDLERS holds
them), and `run_step`, which finds a step's handler there.

A handler takes the running Session and one checked Step, drives the robot through the session's link, and
returns a few words on what was done; it raises StepFailed (with a reason for a person) or lets Interrupted
(a stop or a preemption) pass through.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Awaitable, Callable
from contextlib import AsyncExitStack

from redis.exceptions import RedisError

import alerts
import live
from execution import blocking, driving, traffic, traffic_fleet, traffic_state
from execution.link import LinkError
from execution.make_way import aside, until_passed
from execution.models import Execution, Photo
from execution.route import reach_radius
from execution.spots import ground
from execution.steps import (
    REDIS_LOST,
    STALL_S,
    Interrupted,
    Late,
    Session,
    Stalled,
    StepFailed,
    at_rest,
    drive,
    follow_goal,
    travel_time,
)
from fleetcore import actions, images, motion, outcomes
from fleetcore import traffic_tuning as tune
from fleetcore.speed import Pace
from fleetcore.states import Event
from fleetcore.steps import Destination, Step, parse_task
from fleetcore.traffic import compass
from robots import poses as pose_store
from robots.models import Robot

STALL_TRIES, BACK_OFF_S = 2, 1.0  # after a stall: back off and plan again (or send the goal afresh) twice
BACK_REVERSE = 0.25  # of the robot's top speed, backing off
NEAR_M = 0.3  # m between two robots' reach discs: the other one is what stands in the way
DOCK_LIMIT_S = 120.0
PHOTO_WAIT_S = 5.0  # for the camera's next frame (TIAGo's, simulated, comes twice a second)
STUCK = "robot_stuck"  # the alert kind a stall raises


async def go_to(session: Session, step: Step) -> str:
    """Move (or navigate) to the step's destination, then do its task there if it has one. What it did is
    said from where the robot stands at the end (_arrive), whatever its controller or nav stack returned."""
    if step.destination is None:
        return await task(session, step) if step.task else "arrived at its place"
    pace = step.pace(session.link.limits())
    ending = await _arrive(session, step.destination, pace)
    facing = await _face(session, step.destination.yaw, pace) if step.destination.yaw is not None else ""
    return f"{ending.words}{facing}" + (f"; {await _task(session, step, ending.where)}" if step.task else "")


async def _arrive(session: Session, destination: Destination, pace: Pace) -> outcomes.Ending:
    """Travel to the destination and judge, by the robot's pose at the end (fleetcore.outcomes), where it
    ended: at the place, at the free spot it was given next to it, or elsewhere, which fails the step."""
    spot = await _travel(session, destination, pace)
    ending = await ending_at(session, destination, spot)
    if not ending.reached:
        raise StepFailed(f"{session.robot.name}: {ending.words}")
    return ending


async def ending_at(session: Session, destination: Destination, spot) -> outcomes.Ending:
    """Where the robot ended, sent to the destination and given `spot` to stop at: from its odometry once at
    rest (steps.at_rest), which the pose store then holds too (what every page and query reads)."""
    pose = await at_rest(session)
    return await blocking.call(_judge, session.robot, destination, spot, pose)


def _judge(robot: Robot, destination: Destination, spot, pose) -> outcomes.Ending:
    """ending_at's judgement (the pose kept first, so every page and query reads it)."""
    pose_store.store_pose(robot.pk, pose)
    place, center = destination.place
    taken_by = in_the_way(robot, center, center, "goal")[0] or destination.taken_by
    return outcomes.judge(place, center, spot, pose, taken_by, fits=ground(robot)(*center))


async def make_way(session: Session, step: Step) -> str:
    """Move off the way of a robot that cannot get past this one (it asked, through the traffic table, or a
    person did), wait for it to pass and come back to where this one stood."""
    robot = session.robot
    request = await blocking.call(traffic_state.way_request, robot)
    if request is None:
        return "nobody is waiting for it to make way"
    other = await blocking.call(traffic_fleet.name_of, request["for"])
    try:
        home = (await session.pose())[:2]
        spot = await blocking.call(aside, robot, home, request)
        if spot is None:
            raise StepFailed(f"{robot.name}: no free spot off {other}'s way within {tune.ASIDE_SEARCH_M:g} m")
        await _transition(session, Event.MOVE, f"making way for {other}")
        session.making_way = True
        pace = step.pace(session.link.limits())
        await _go(session, spot, pace)
        waited = await until_passed(session, request, home)
        back = await ending_at(session, Destination("where it stood", *home), await _go(session, home, pace))
    except BaseException as exc:  # failed or stopped: the robot waiting for it asks nobody else, goes round
        await asyncio.shield(blocking.call(traffic_state.made_way, robot, str(exc) or type(exc).__name__))
        raise
    await blocking.call(traffic_state.made_way, robot)
    return (
        f"made way for {other}: {math.dist(home, spot):.1f} m {compass(home, spot)}, "
        f"back after {waited:.0f} s" + ("" if back.kind == outcomes.ARRIVED else f" ({back.words})")
    )


async def _transition(session: Session, event: Event, words: str) -> None:
    """The robot's state says what it does now (robots.models: the fleet's state machine)."""
    robot, instruction = session.robot.pk, session.execution.instruction_id
    await blocking.call(Robot.objects.transition, robot, event, words, instruction)


async def _alert(session: Session, words: str) -> None:
    await blocking.call(alerts.raise_alert, STUCK, session.robot, words, session.execution.event)


async def _go(session: Session, goal, pace: Pace) -> tuple[float, float]:
    """To a point along a reserved route, by the robot's own navigation or the route driver; the spot it was
    to stop at (the goal, or a free spot next to it when a robot stood there)."""
    if session.link.nav_kind:
        return await navigate_to(session, tuple(goal), pace)
    return await drive_route(session, tuple(goal), pace)


async def _face(session: Session, yaw: float, pace: Pace) -> str:
    """Turn on the spot to the heading the goal was given with."""
    try:
        await drive(
            session,
            motion.Face(yaw, pace.limits),
            travel_time(0.0, math.pi, pace.limits),
            stall_s=STALL_S,
        )
    except Stalled as exc:
        raise StepFailed(await _stuck(session, "turning to its heading", str(exc))) from exc
    return f", facing {math.degrees(yaw):.0f}°"


async def task(session: Session, step: Step) -> str:
    """rotate(n) on the spot or clean a small square, where the robot is, or at the step's destination."""
    if step.destination is None:
        return await _task(session, step, "at its place")
    ending = await _arrive(session, step.destination, step.pace(session.link.limits()))
    return f"{ending.words}; {await _task(session, step, ending.where)}"


async def _task(session: Session, step: Step, where: str) -> str:
    """Do the step's task where the robot stands (`where`, in words: "at A"); a task whose entry names a
    handler of its own (photograph) is that handler's."""
    name, count = parse_task(step.task or step.action)
    own = actions.ACTIONS[name].handler
    if own != "task":
        return f"{await HANDLERS[own](session, step)} {where}"
    await _transition(session, Event.WORK, f"{name} {where}")
    pose = await session.pose()
    limits = step.pace(session.link.limits()).limits
    controller = motion.task_controller(step.task or step.action, pose, limits)
    if name == "rotate":
        limit = travel_time(0.0, 2 * math.pi * count, limits)
    else:
        limit = travel_time(motion.CLEAN_SIZE * (motion.CLEAN_LANES + 2), 2 * math.pi * 3, limits)
    try:
        await drive(session, controller, limit, stall_s=STALL_S)
    except Stalled as exc:
        raise StepFailed(await _stuck(session, f"during {step.task or name} {where}", str(exc))) from exc
    return f"{step.task or name} done {where}"


async def dock(session: Session, step: Step) -> str:
    """Dock: the robot's own docking action where it has one, else drive to its start pose ("home")."""
    robot = session.robot
    await _transition(session, Event.MOVE, "docking")
    if session.link.can_dock:
        session.check()
        goal = await session.link.dock()
        await session.mark_commanded()
        await follow_goal(session, goal, DOCK_LIMIT_S, "docking", stall_s=tune.NAV_STALL_S, toward=False)
        return "docked"
    x0, y0, _ = robot.start_pose or (0.0, 0.0, 0.0)
    ending = await _arrive(session, Destination("its start pose", x0, y0), step.pace(session.link.limits()))
    return f"{ending.words} (no docking action bound)"


async def photograph(session: Session, step: Step) -> str:
    """Take the next frame of the robot's camera and keep it with the execution (Photo); nothing moves."""
    robot = session.robot
    await _transition(session, Event.WORK, "taking a photo")
    try:
        image = images.from_message(await session.link.photo(PHOTO_WAIT_S, between=session.check))
    except (LinkError, images.FrameError) as exc:
        raise StepFailed(f"{robot.name}: no photo ({str(exc).removeprefix(robot.name + ': ')})") from exc
    await blocking.call(
        Photo.objects.create,
        execution=session.execution, image=image.data, format=image.format, width=image.width,
        height=image.height, topic=session.link.camera.target,
    )  # fmt: skip
    return f"took a photo ({image.width}×{image.height} {image.format.upper()})"


async def move_by(session: Session, step: Step) -> str:
    """Drive straight ahead (or back) by the step's amount in metres, holding the heading it starts with."""
    distance = float(step.amount or 0.0)
    doing = f"{abs(distance):g} m {'forward' if distance >= 0 else 'back'}"
    limits = step.pace(session.link.limits()).limits
    controller = motion.Straight(distance, limits)
    limit = travel_time(abs(distance), 0.0, limits)
    return await _drive_by(
        session, f"moving {doing}", controller, limit, lambda done: outcomes.moved(distance, done)
    )


async def turn_by(session: Session, step: Step) -> str:
    """Turn on the spot by the step's amount in degrees (left, anticlockwise, when positive)."""
    degrees = float(step.amount or 0.0)
    doing = f"{abs(degrees):g}° {'left' if degrees >= 0 else 'right'}"
    limits = step.pace(session.link.limits()).limits
    controller = motion.TurnBy(math.radians(degrees), limits)
    limit = travel_time(0.0, abs(math.radians(degrees)), limits)
    return await _drive_by(
        session,
        f"turning {doing}",
        controller,
        limit,
        lambda done: outcomes.turned(degrees, math.degrees(done)),
    )


async def _drive_by(
    session: Session, doing: str, controller, limit: float, said: Callable[[float], str]
) -> str:
    """A relative motion: the robot's state says what it does; the words of how far it went, measured where it
    came to rest (said: the controller's measure in words). A step that stalls or runs out of time fails with
    those words too: "did not finish within 12 s" alone left out that it had turned 60° of the 90° asked."""
    await _transition(session, Event.MOVE, doing)
    try:
        await drive(session, controller, limit, stall_s=STALL_S)
    except (Stalled, Late) as exc:
        so_far = said(controller.done(await at_rest(session)))
        reason = await _stuck(session, doing, str(exc)) if isinstance(exc, Stalled) else str(exc)
        raise StepFailed(f"{reason}: {so_far}") from exc
    return said(controller.done(await at_rest(session)))


async def wait(session: Session, step: Step) -> str:
    """Stay where it is for the step's amount in seconds, standing still, while stops and preemptions work."""
    seconds = float(step.amount or 0.0)
    await session.link.halt()
    until = time.monotonic() + seconds
    while time.monotonic() < until:
        await session.pose()  # keeps the lease and sees a dropped link
        session.check()
    return f"waited {seconds:g} s"


MIN_ROUND_S = 1.0  # a round of a repeat takes at least this long (a loop of steps with nothing left to do)


async def repeat(session: Session, step: Step) -> str:
    """Run the `span` steps before this one again, `amount` more times or, without an amount, until stopped.

    The execution's step index stays on this step while it loops, so a preempted loop goes on when resumed.
    """
    index = await blocking.call(_step_index, session.execution.pk)
    body = session.execution.steps[max(0, index - (step.span or 1)) : index]
    if not body:
        raise StepFailed(f"{session.robot.name}: there is nothing before the repeat to do again")
    rounds = 0
    while step.amount is None or rounds < step.amount:
        started = time.monotonic()
        for item in body:
            await run_step(session, item)
        rounds += 1
        while time.monotonic() - started < MIN_ROUND_S:
            await session.pose()
            session.check()
    return f"repeated {len(body)} step(s) {rounds} more time(s)"


def _step_index(execution_id: int) -> int:
    return Execution.objects.filter(pk=execution_id).values_list("step_index", flat=True).get()


async def report_position(session: Session, step: Step) -> str:
    x, y, yaw = await session.pose()
    return f"{session.robot.name} is at ({x:.2f}, {y:.2f}), heading {math.degrees(yaw):.0f}°"


async def _travel(session: Session, destination: Destination, pace: Pace) -> tuple[float, float]:
    """Get to the destination along a reserved route (execution.traffic), by the robot's own navigation or the
    route driver; a stall says what blocks it, and any failure where the robot stopped. Returns the spot it was
    to stop at: the destination, or a free spot next to it when a robot stood there."""
    x, y, name = destination.x, destination.y, destination.name
    await _transition(session, Event.MOVE, f"moving to {name}")
    await blocking.call(live.goal, session.robot, name, x, y)  # the map draws the goal till the robot is done
    try:
        return await _go(session, (x, y), pace)
    except StepFailed as exc:
        explained = await blocking.call(_explain, session, destination, exc)
        raise StepFailed(explained + _stopped(session, destination)) from exc
    finally:
        await asyncio.shield(blocking.call(live.goal, session.robot, None, None, None))


def _stopped(session: Session, destination: Destination) -> str:
    """ "; it stopped 0.8 m north of A": where a robot whose step failed on the way stands (its last pose)."""
    pose = session.link.poses.value
    if pose is None:
        return ""
    place, center = destination.place
    return f"; it stopped {outcomes.offset(place, center, pose[:2])}"


async def navigate_to(session: Session, goal: tuple[float, float], pace: Pace) -> str:
    """Hand the reserved route's goals to the robot's nav stack at the step's pace; when it makes no progress,
    send them afresh (a new plan from where the robot is, with what its sensors see now), up to STALL_TRIES
    times. A stack that aborts has tried its own recoveries already: that ends the step.

    The speed word is kept on the stack's own top speed (`Pace.stack_share`): nav2 through its controller's
    speed limit, move_base through its local planner's max_vel_x. A stack that takes no limit is not asked:
    the portal drives the route itself at that pace. A limit the stack refuses fails the step before any goal
    is sent."""
    share = pace.stack_share
    if share is not None and not session.link.surface.can_limit_speed:
        return await drive_route(session, goal, pace)
    async with AsyncExitStack() as held:
        if session.link.surface.can_limit_speed:
            try:
                await held.enter_async_context(session.link.speed_limited(share))
            except LinkError as exc:
                raise StepFailed(str(exc)) from exc
        for attempt in range(STALL_TRIES + 1):
            try:
                return await driving.travel(session, goal, pace, nav=True)
            except Stalled as exc:
                await _stalled(session, exc, attempt)
    return ""


async def drive_route(session: Session, goal: tuple[float, float], pace: Pace) -> str:
    """Drive a reserved route (execution.driving: planned in space and time, claimed stretch by stretch) with the
    Figure 7 controller: loose at the corners, within tolerance at the goal.

    Stalled on the way (something the plan did not know), the robot backs off a little and plans again from
    where it is, with the other robots' live poses and reservations, up to STALL_TRIES times.
    """
    for attempt in range(STALL_TRIES + 1):
        try:
            return await driving.travel(session, goal, pace)
        except Stalled as exc:
            await _stalled(session, exc, attempt)
            await back_off(session, pace.top)
    return ""


async def _stalled(session: Session, exc: Stalled, attempt: int) -> None:
    """A stall: the first one raises the robot_stuck alert; the last try's ends the step."""
    if attempt == 0:
        await _alert(session, f"{exc} (trying again)")
    if attempt == STALL_TRIES:
        raise Stalled(f"{exc}; tried {STALL_TRIES + 1} times", exc.pose)


def _explain(session: Session, destination: Destination, exc: StepFailed) -> str:
    """The failure in a person's words: the robot in the way when one stands at the goal or at the robot
    (off the loop: it reads the fleet)."""
    blocked = isinstance(exc, Stalled) or str(exc).endswith("navigation aborted")
    pose = getattr(exc, "pose", None) or session.link.poses.value
    if not blocked or pose is None:
        return str(exc)
    detail = str(exc).removeprefix(f"{session.robot.name}: ")
    other, where = in_the_way(session.robot, pose[:2], (destination.x, destination.y))
    if other is None:
        return f"{session.robot.name}: stuck on the way to {destination.name} ({detail})"
    place = (
        destination.name
        if where == "goal"
        else f"({pose[0]:.1f}, {pose[1]:.1f}) on the way to {destination.name}"
    )
    reason = f"{session.robot.name}: blocked by {other} at {place} ({detail})"
    alerts.raise_alert(STUCK, session.robot, reason, session.execution.event)
    return reason


async def _stuck(session: Session, what: str, detail: str) -> str:
    reason = f"{session.robot.name}: stuck {what} ({detail.removeprefix(session.robot.name + ': ')})"
    await _alert(session, reason)
    return reason


def in_the_way(
    robot: Robot, at: tuple[float, float], goal: tuple[float, float], only: str = ""
) -> tuple[str | None, str]:
    """(the name of the robot standing at the goal, or else next to `at`, by their last poses; "goal"/"here").
    only: "goal" looks at the goal only.

    Two robots touch when their reach discs (half their footprints' diagonals) meet; NEAR_M more is allowed
    for odometry and the pose store's age.
    """
    others = {other.pk: other for other in Robot.objects.exclude(pk=robot.pk).only("pk", "name", "footprint")}
    poses = pose_store.last_poses(list(others))
    mine = reach_radius(robot.footprint)
    for spot, where in ((goal, "goal"), (at, "here"))[: 1 if only == "goal" else 2]:
        near = [
            (math.dist(spot, (pose["x"], pose["y"])), others[pk].name)
            for pk, pose in poses.items()
            if math.dist(spot, (pose["x"], pose["y"])) < reach_radius(others[pk].footprint) + mine + NEAR_M
        ]
        if near:
            return min(near)[1], where
    return None, ""


async def back_off(session: Session, limits: motion.Limits) -> None:
    """Reverse slowly for a moment, to leave room to turn: only into room it has claimed (a robot standing or
    waiting behind it keeps it where it is; run w: a Husky that stalled backed blind into a TurtleBot)."""
    x, y, yaw = await session.pose()
    reach = BACK_REVERSE * limits.linear * BACK_OFF_S * session.link.clock.rate + tune.APPROACH_SLACK
    behind = (x - reach * math.cos(yaw), y - reach * math.sin(yaw))
    if await blocking.call(traffic.claim, session.robot, (x, y), behind, session.check) is not None:
        return
    until = time.monotonic() + BACK_OFF_S
    while time.monotonic() < until:
        await session.send(-BACK_REVERSE * limits.linear, 0.0)
        await session.pose()
    await session.link.halt()


HANDLERS: dict[str, Callable[[Session, Step], Awaitable[str]]] = {
    handler.__name__: handler
    for handler in (go_to, task, dock, make_way, report_position, move_by, turn_by, wait, repeat, photograph)
}  # the functions the registry's entries name (fleetcore.actions.Action.handler)


async def run_step(session: Session, step: dict) -> str:
    """Run one step with its action's handler (fleetcore/actions.py, HANDLERS); return a few words on what was
    done. A Redis error from anywhere in the handler (e.g. releasing its route as the step ends) is the
    executor's loss of Redis, said in a person's words."""
    checked = Step.from_dict(step)
    handler = HANDLERS.get(checked.spec.handler or "")
    if handler is None:
        raise StepFailed(f"{session.robot.name}: {checked.action!r} is not something the executor runs")
    try:
        return await handler(session, checked)
    except RedisError as exc:
        raise Interrupted("failed", f"{REDIS_LOST} ({exc})") from exc
