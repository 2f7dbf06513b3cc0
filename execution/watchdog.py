"""Find executions whose executor is lost, stop their robots and fail them; restart robots' stalled queues.

A running execution carries the token of the runner that claimed it, and that runner's process renews the
robot's lock under the same token every quarter second (execution.board). The executor is lost when the lock is
gone or held by another token (the process killed, frozen, or its host gone: LOST, up to LOCK_TTL_MS after), or
when the process that holds it is gone (GONE): its presence subscription (coordination.present), which Redis
drops as soon as the process's socket closes, missing at two looks GONE_S apart. A kill -9 or a crash is then
seen a quarter to half a second after it, not a second or more: a turtlebot killed mid-turn at 2.4 rad/s came to
rest 1.6-2.0 s after it by the lock's lapse (0.76 s of that braking), 0.8-1.1 s by its presence (tests/chaos).
A frozen process keeps its socket: its lock lapses.

The scheduler process, which stays up, looks every WATCHDOG_S: the robot gets a zero velocity and its
navigation goal is cancelled at once, the execution is failed with the reason "executor lost", its instruction
settled, its traffic reservations dropped (others then go round it as a robot standing there, instead of
waiting out their lapse), and an executor_lost alert raised. To send that zero at once, the scheduler keeps a
link open to the endpoint of every robot being driven (keep_links): connecting at that moment cost up to a
second more on a busy machine.

An execution whose runner ended it (its robot halted) while the database refused to record that end is found the
same way once its lock lapses: its runner kept the end's words in Redis (runner._unrecorded), and they are recorded
instead of "executor lost" ("stopped; the database is locked ..."), with no executor_lost alert.

Failed, not resumed: the step was cut at an unknown point (half a rotation, a goal the stack may still hold),
the robot may since have been moved or stopped by hand, and a robot that starts moving by itself after a
crash is the worse surprise. A person sees the alert and sends the instruction again if it still makes sense
(docs/fault-survival.md).
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from concurrent.futures import TimeoutError as FuturesTimeout
from datetime import timedelta

from django.db import connections
from django.utils import timezone

import alerts
from execution import coordination, executor, traffic_state
from execution.link import publish_zero
from execution.models import Execution
from execution.runner import WAITING, settle
from fleetcore.states import Event
from robots.models import Robot
from robots.rosbridge.sync import get_client

log = logging.getLogger(__name__)
STALLED_AFTER = 3.0  # s a queued execution may wait for its task before the robot is kicked
STOP_WAIT_S = 2.0  # s the records wait for a lost executor's robot's zero (it is still sent after)
LOST = "executor lost: the process running it stopped renewing its lock; the robot was stopped"
GONE = "executor lost: the process running it is gone (its connection to Redis closed); the robot was stopped"
GONE_S = 0.2  # s a lock holder's process is missing before it is gone, not reconnecting: two looks at least


def _running(robot_ids=None) -> list[Execution]:
    running = Execution.objects.filter(status=Execution.Status.RUNNING).select_related("robot")
    if robot_ids is not None:
        running = running.filter(robot_id__in=list(robot_ids))
    return list(running)


class _Absences:
    """Since when each lock holder's process has been missing from its presence channel, as of the last look."""

    def __init__(self) -> None:
        self.since: dict[str, float] = {}

    def gone(self, processes: set[str]) -> set[str]:
        """The processes missing for GONE_S or more (at two looks at least), of these."""
        now = time.monotonic()
        present = coordination.present(processes)
        self.since = {process: self.since.get(process, now) for process, here in present.items() if not here}
        return {process for process, since in self.since.items() if now - since >= GONE_S}


_absences = _Absences()


def _lost(running: list[Execution]) -> dict[Execution, str]:
    """{execution: why} for those whose executor is lost: their robot's lock lapsed or taken (LOST), or held by
    a process gone (GONE): its lock is then released, so a live holder (its presence lost, not its life) stops
    too, and another executor takes the robot at once."""
    holders = coordination.lock_holders({execution.robot_id for execution in running})
    lost, held = {}, {}
    for execution in running:
        if holders.get(execution.robot_id) != execution.worker:
            lost[execution] = LOST
        elif process := coordination.holder_process(execution.worker):
            held[execution] = process
    gone = _absences.gone(set(held.values()))  # every pass: a look with none held forgets the absences
    for execution, process in held.items():
        if process in gone:
            lost[execution] = GONE
            coordination.RobotLock(execution.robot_id, execution.worker).release()
    return lost


def recover(robot_ids=None) -> list[int]:
    """Stop the robots of lost executions, fail those executions and settle them; return their keys."""
    running = _running(robot_ids)
    keep_links(execution.robot.endpoint for execution in running)
    lost = _lost(running)
    said = coordination.unrecorded_ends(execution.pk for execution in lost) if lost else {}
    why = {execution.pk: said.get(execution.pk, reason) for execution, reason in lost.items()}
    failed = [execution for execution in lost if _claim_failure(execution, why[execution.pk])]
    if not failed:
        return []
    started = time.monotonic()
    stops = {_stopping.submit(_stop, execution.robot): execution for execution in failed}
    pending = dict(stops)
    try:  # each robot's bookkeeping once its own zero is out: a slow or unreachable robot delays no other
        for done in as_completed(stops, timeout=STOP_WAIT_S):
            execution = pending.pop(done)
            _fail(execution, why[execution.pk], execution.pk in said)
    except FuturesTimeout:  # its zero still being sent (the stop goes on): the record does not wait for it
        log.warning(
            "executor lost: zeros not out after %.1f s to %s",
            STOP_WAIT_S,
            [e.robot.name for e in pending.values()],
        )
        for execution in pending.values():
            _fail(execution, why[execution.pk], execution.pk in said)
    log.info(
        "executor lost: %d robots stopped and settled in %.2f s", len(failed), time.monotonic() - started
    )
    return [execution.pk for execution in failed]


def _fail(execution: Execution, why: str, unrecorded: bool) -> None:
    """The records of one lost execution: its claims freed, its robot failed, its instruction settled, an alert
    (unrecorded: its runner ended it and the database refused the record, so no executor was lost)."""
    # its route and claims, which nobody renews now, free at once
    traffic_state.release(execution.robot, None)
    Robot.objects.transition(execution.robot_id, Event.FAIL, why[:255], execution.instruction_id)
    settle(execution.instruction_id)
    if unrecorded:
        coordination.forget_unrecorded_end(execution.pk)
        return
    alerts.raise_alert(
        "executor_lost", execution.robot, f"instruction #{execution.instruction_id}: {why}", execution.event
    )


_linking = ThreadPoolExecutor(max_workers=4, thread_name_prefix="watchdog link")
_stopping = ThreadPoolExecutor(max_workers=16, thread_name_prefix="watchdog stop")
_linked: set[str] = set()  # endpoints this process has a link to (robots.rosbridge.sync keeps it up)


def keep_links(endpoints) -> None:
    """Open, in the background and once, a link to the endpoint of every robot being driven: the zero after
    its executor's loss then goes out on a link that is up, not after a connect (a second on a busy machine)."""
    for endpoint in {endpoint for endpoint in endpoints if endpoint} - _linked:
        _linked.add(endpoint)
        _linking.submit(_open_link, endpoint)


def _open_link(endpoint: str) -> None:
    try:
        get_client(endpoint)
    except Exception as exc:  # unreachable now: the next look tries again
        _linked.discard(endpoint)
        log.info("%s: no link for the watchdog yet: %s", endpoint, exc)


def _claim_failure(execution: Execution, why: str = LOST) -> bool:
    """Fail the execution unless its runner finished it meanwhile (a conditional update: one writer wins)."""
    return bool(
        Execution.objects.filter(
            pk=execution.pk, status=Execution.Status.RUNNING, worker=execution.worker
        ).update(status=Execution.Status.FAILED, finished_at=timezone.now(), error=why[:2000])
    )


def _stop(robot: Robot) -> None:
    """Zero velocity and a move_base cancel (a nav2 goal is cancelled by rosbridge when its client dies)."""
    try:
        publish_zero(robot)
    except Exception as exc:  # report, and still settle the instruction
        log.warning("%s: could not stop after its executor was lost: %s", robot.name, exc)
    finally:
        connections.close_all()  # this pool thread's own; none is left open between losses


def stalled_robots() -> list[int]:
    """Robots with waiting executions and nobody holding their lock."""
    settled = timezone.now() - timedelta(seconds=STALLED_AFTER)  # give the task its time to be picked up
    waiting = Execution.objects.filter(status__in=WAITING, created_at__lt=settled)
    robot_ids = sorted(set(waiting.values_list("robot_id", flat=True)))
    holders = coordination.lock_holders(robot_ids)
    return [rid for rid in robot_ids if holders[rid] is None]


def kick_stalled() -> list[int]:
    """Wake the executors for the stalled robots, in one message (each robot at most once every few seconds)."""
    kicked = [
        robot_id
        for robot_id in stalled_robots()
        if coordination.connection().set(coordination.key("kick", robot_id), 1, nx=True, ex=5)
    ]
    executor.wake(kicked)
    return kicked
