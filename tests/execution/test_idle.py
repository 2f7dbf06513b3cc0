"""The scheduler's idle pass: a robot ready (or in a dialog) past its timeout is moved on, picked by the database."""

import datetime

import pytest
from django.utils import timezone

from execution import scheduler
from robots.models import Robot, StateTransition

pytestmark = pytest.mark.django_db


def robot(name: str, state: str, registered_s: float, last_s: float | None, now) -> Robot:
    """A robot registered registered_s ago whose last transition (None: none) was last_s ago."""
    made = Robot.objects.create(
        name=name, endpoint="ws://127.0.0.1:1", namespace=f"/{name}", state=state,
        registered_at=now - datetime.timedelta(seconds=registered_s),
    )  # fmt: skip
    if last_s is not None:
        at = now - datetime.timedelta(seconds=last_s)
        StateTransition.objects.create(robot=made, from_state="offline", to_state=state, at=at)
        StateTransition.objects.create(
            robot=made, from_state="offline", to_state="offline", at=at - datetime.timedelta(hours=1)
        )
    return made


def test_idle_robots_go_offline_and_unanswered_dialogs_end_the_busy_and_fresh_stay(settings):
    settings.FLEET_IDLE_TIMEOUT_SECONDS = 600
    now = timezone.now()
    idle = robot("idle", "ready", 5000, 601, now)  # its newest transition is what counts, not the older one
    fresh = robot("fresh", "ready", 5000, 30, now)
    never = robot("never", "ready", 700, None, now)  # no transition: its registration counts
    new = robot("new", "ready", 60, None, now)
    asked = robot("asked", "dialog", 5000, scheduler.DIALOG_TIMEOUT + 5, now)
    moving = robot("moving", "motion", 5000, 5000, now)
    scheduler.expire_idle(now)
    states = dict(Robot.objects.values_list("name", "state"))
    assert states == {
        idle.name: "offline", never.name: "offline", fresh.name: "ready", new.name: "ready",
        asked.name: "ready", moving.name: "motion",
    }  # fmt: skip
    reasons = dict(StateTransition.objects.filter(reason__gt="").values_list("robot__name", "reason"))
    assert reasons == {"idle": "idle for 600 s", "never": "idle for 600 s", "asked": "no answer for 120 s"}
