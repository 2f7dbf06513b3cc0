"""The scheduler loop: scheduled time slots run by themselves; lost executors, stalled queues and anything left
unfinished are handled.

Every WATCHDOG_S (a quarter second), the watchdog stops the robots of executors that stopped heartbeating and
fails their executions ("executor lost"). One tick (every half second in `python manage.py scheduler`):
1. robots with queued executions and no runner are woken again (their executor's sweep finds them too);
2. each enabled time slot that covers now and has not run today becomes an instruction (source "schedule");
   instructions waiting for a free robot are allocated when one is free (execution.dispatch.retry);
3. every SLOW_S (five seconds), robots in dialog with no answer for DIALOG_TIMEOUT go back to ready; robots idle
   in ready longer than FLEET_IDLE_TIMEOUT_SECONDS go offline (they wake on the next instruction);
4. and the sweeps finish what has no owner any more (execution/sweeps.py: stale received instructions,
   unanswered questions, work queued for robots offline, instructions whose settle was lost).

The clock is injectable: Clock(start, scale) runs schedules time-compressed (tests, demos).
"""

from __future__ import annotations

import datetime
import logging
import time
from dataclasses import dataclass, field

from django.conf import settings
from django.db import close_old_connections
from django.db.models import Max
from django.db.models.functions import Coalesce
from django.utils import timezone

from execution import coordination, dispatch, sweeps, watchdog
from execution.instructions import submit
from execution.models import TimeSlot
from fleetcore.interpretation import Interpretation
from fleetcore.states import Event
from robots.models import Robot

log = logging.getLogger(__name__)
DIALOG_TIMEOUT = 120.0  # s


@dataclass
class Clock:
    """Wall time, or a compressed clock that starts at `start` and runs `scale` times faster."""

    start: datetime.datetime | None = None
    scale: float = 1.0
    _t0: float = field(default_factory=time.monotonic)

    def now(self) -> datetime.datetime:
        if self.start is None:
            return timezone.now()
        return self.start + datetime.timedelta(seconds=(time.monotonic() - self._t0) * self.scale)


def slot_text(slot: TimeSlot) -> str:
    task = f" and {slot.task}" if slot.task else ""
    return f"move {slot.robot.name} to {slot.goal.name}{task}"


def slot_parse(slot: TimeSlot) -> Interpretation:
    """The instruction a slot stands for (no interpreter needed: the slot is already structured)."""
    goal = slot.goal
    destination = {"name": goal.name, "x": goal.x, "y": goal.y}
    return Interpretation.for_robots(
        [slot.robot.name], "move", "schedule", destination, task=slot.task or None
    )


def run_due_slots(moment: datetime.datetime) -> list:
    """Start every enabled slot covering this moment that has not run on its date; return the instructions."""
    local = timezone.localtime(moment)
    today, now = local.date(), local.time()
    due = TimeSlot.objects.filter(enabled=True, start__lte=now, end__gt=now).exclude(last_run_on=today)
    started = []
    for slot in due.select_related("robot", "goal"):
        claimed = TimeSlot.objects.filter(pk=slot.pk).exclude(last_run_on=today).update(last_run_on=today)
        if claimed:
            text = f"{slot_text(slot)} (schedule {slot.start:%H:%M}-{slot.end:%H:%M})"
            started.append(submit(text, None, source="schedule", parse=slot_parse(slot)))
    return started


def expire_idle(now: datetime.datetime) -> None:
    """Dialogs without an answer end; robots idle in ready past the idle timeout go offline.

    The database picks them (last transition, else registration, before the cutoff): a pass reads no row of a
    robot that is not idle, where it built every ready robot twice a second (a third of the scheduler's Python
    samples at 100 robots; its CPU 0.9x, bench/results/cost/)."""
    limits = {Robot.State.DIALOG: DIALOG_TIMEOUT, Robot.State.READY: settings.FLEET_IDLE_TIMEOUT_SECONDS}
    events = {Robot.State.DIALOG: (Event.DONE, "no answer"), Robot.State.READY: (Event.IDLE_TIMEOUT, "idle")}
    for state, limit in limits.items():
        idle = (
            Robot.objects.filter(state=state)
            .annotate(last=Coalesce(Max("transitions__at"), "registered_at"))
            .filter(last__lt=now - datetime.timedelta(seconds=limit))
            .values_list("pk", flat=True)
        )
        event, reason = events[state]
        for pk in list(idle):
            Robot.objects.transition(pk, event, f"{reason} for {limit:.0f} s")


def watch() -> dict:
    """The fast pass: robots of lost executors stopped, their executions failed."""
    close_old_connections()
    return {"recovered": watchdog.recover()}


SLOW_S = 5.0  # between the slow passes (idle timeouts, sweeps): what they look for is a minute old or more


def tick(clock: Clock, slow: bool = True) -> dict:
    """One pass of the loop; return what it did (for logs and tests). slow: also the idle timeouts and the
    sweeps, whose limits are a minute and more (the loop runs them every SLOW_S, not every tick: at 100
    robots they were a third of the scheduler's CPU)."""
    close_old_connections()
    report = {"recovered": watchdog.recover(), "kicked": watchdog.kick_stalled()}
    report["scheduled"] = [instruction.pk for instruction in run_due_slots(clock.now())]
    report["allocated"] = dispatch.retry()  # instructions that waited for a free robot
    if slow:
        expire_idle(timezone.now())
        report.update(sweeps.sweep())
    return report


def loop(
    clock: Clock,
    period: float = 0.5,
    should_stop=lambda: False,
    watch_every: float = coordination.WATCHDOG_S,
    beat=lambda: None,
    slow_every: float = SLOW_S,
) -> None:
    """Watch every watch_every, tick every period and make the tick slow every slow_every until should_stop()
    says so; a failing pass is logged. beat() at every pass: the process's heartbeat (a pass that hangs is seen
    as hung)."""
    next_tick = next_slow = time.monotonic()
    while not should_stop():
        beat()
        started = time.monotonic()
        if started >= next_tick:
            slow = started >= next_slow
            _logged(tick, clock, slow)
            next_tick = started + period
            next_slow = started + slow_every if slow else next_slow
        else:
            _logged(watch)
        time.sleep(max(0.0, min(watch_every, period) - (time.monotonic() - started)))


def _logged(run, *args) -> None:
    try:
        report = run(*args)
    except Exception:
        log.exception("scheduler pass failed")
        return
    if any(report.values()):
        log.info("scheduler: %s", report)
