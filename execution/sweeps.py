"""Nothing stays unfinished: each non-final status has an owner that finishes it, and a sweep with a deadline
for when the owner is gone. The scheduler process runs sweep() every tick.

| status                    | owner                                         | sweep (deadline)                          |
|---------------------------|-----------------------------------------------|-------------------------------------------|
| Execution running         | its runner, heartbeating the robot's lock     | watchdog.recover (the lock's 1 s); an end |
|                           | (an end the database refused: kept in Redis)  | kept in Redis is recorded with its words  |
| Execution queued/preempted| the runner holding the robot; kick_stalled    | robot offline for OFFLINE_S: failed       |
| Instruction received      | submit (one transaction)                      | RECEIVED_S: failed                        |
| Instruction needs_user    | the person's answer (submit answer_to)        | answer_s(): cancelled, "expired: no answer|
|                           |                                               | within 10 min"                            |
| Instruction queued/running| runner.settle when its last execution ends    | all executions final: settled; none at    |
|                           |                                               | all after RECEIVED_S: failed              |
"""

from __future__ import annotations

from datetime import timedelta

from django.conf import settings
from django.db.models import Count, Q
from django.utils import timezone

from execution.instructions import close_dialog
from execution.models import EXPIRED, Execution, ExecutionQuerySet, Instruction
from execution.runner import settle

RECEIVED_S = 60.0  # storing, interpreting and dispatching is one transaction: a minute is far past it
OFFLINE_S = 30.0  # queued work for a robot nobody has seen for this long fails ("robot offline")
NOT_DISPATCHED = "not dispatched: the process storing it stopped before it was handed to a robot"
ROBOT_OFFLINE = "robot offline: its link has been down for more than {:.0f} s"


def sweep(now=None) -> dict[str, list[int]]:
    """Run every sweep once; return what each finished (for the scheduler's log and tests)."""
    now = now or timezone.now()
    return {
        "received": fail_stale_received(now),
        "needs_user": cancel_unanswered(now),
        "offline": fail_waiting_for_offline(now),
        "unsettled": settle_orphans(now),
    }


def fail_stale_received(now) -> list[int]:
    """Instructions still "received" a minute on: their submit died midway; fail them, saying so."""
    stale = list(Instruction.objects.older_than("received", RECEIVED_S, now).values_list("pk", flat=True))
    Instruction.objects.filter(pk__in=stale, status="received").update(
        status=Instruction.Status.FAILED, outcome=NOT_DISPATCHED, finished_at=now
    )
    return stale


def answer_s() -> float:
    """How long a question waits for its answer (settings.FLEET_QUESTION_EXPIRY_SECONDS)."""
    return float(settings.FLEET_QUESTION_EXPIRY_SECONDS)


def expiry_note(seconds: float) -> str:
    """ "expired: no answer within 10 min" (or "within 90 s")."""
    within = f"{seconds / 60:g} min" if seconds % 60 == 0 else f"{seconds:g} s"
    return f"{EXPIRED} {within}"


def cancel_unanswered(now) -> list[int]:
    """Questions nobody answered within answer_s(): expired with a note, their robots back to ready."""
    limit = answer_s()
    unanswered = list(Instruction.objects.older_than("needs_user", limit, now, since="interpreted_at"))
    for instruction in unanswered:
        close_dialog(instruction, expiry_note(limit))
    return [instruction.pk for instruction in unanswered]


def fail_waiting_for_offline(now) -> list[int]:
    """Queued (or preempted) executions of robots offline for OFFLINE_S: failed, their instructions settled."""
    rows = list(
        Execution.objects.waiting_for_offline_robots(OFFLINE_S, now).values_list("pk", "instruction_id")
    )
    Execution.objects.filter(pk__in=[pk for pk, _ in rows]).waiting().update(
        status=Execution.Status.FAILED, finished_at=now, error=ROBOT_OFFLINE.format(OFFLINE_S)
    )
    for instruction_id in {iid for _, iid in rows}:
        settle(instruction_id)
    return [pk for pk, _ in rows]


def settle_orphans(now) -> list[int]:
    """Queued or running instructions whose executions all ended (a settle lost in a crash), or that never
    got any: settle them."""
    active = Instruction.objects.filter(status__in=("queued", "running")).annotate(
        total=Count("executions"),
        unfinished=Count("executions", filter=~Q(executions__status__in=ExecutionQuerySet.FINAL)),
    )
    settled = []
    for instruction in active.filter(total__gt=0, unfinished=0):
        settle(instruction.pk)
        settled.append(instruction.pk)
    empty = active.filter(total=0).filter(received_at__lt=now - timedelta(seconds=RECEIVED_S))
    for pk in list(empty.values_list("pk", flat=True)):
        Instruction.objects.filter(pk=pk, status__in=("queued", "running")).update(
            status=Instruction.Status.FAILED,
            outcome="nothing to run: no robot was given a share",
            finished_at=now,
        )
        settled.append(pk)
    return settled
