"""Redis or the database refusing writes: pages and the API answer 503 with the reason, an alert is raised."""

import sqlite3

import pytest
import redis
from django.db import OperationalError

from alerts.models import Alert
from fleetcore import faults
from portal import middleware, snapshots
from tests.execution.helpers import wait_for

MISCONF = "MISCONF Redis is configured to save RDB snapshots, but it's currently unable to persist to disk."


def test_the_words_name_the_store_and_what_it_refuses():
    assert faults.store_fault(redis.exceptions.ResponseError(MISCONF)).startswith("Redis refuses writes")
    assert "disk full under var/" in faults.store_fault(redis.exceptions.ResponseError(MISCONF))
    assert faults.store_fault(redis.exceptions.ConnectionError("refused")) == "Redis unavailable"
    locked = OperationalError("database is locked")
    assert faults.store_fault(locked) == "the database is locked (another writer holds it)"
    full = sqlite3.OperationalError("database or disk is full")
    assert "disk full" in faults.store_fault(full)
    assert faults.store_fault(ValueError("no")) is None
    assert faults.in_words(TimeoutError(), "Redis") == "Redis does not answer (frozen or overloaded)"


@pytest.fixture
def refusing(monkeypatch):
    """The dashboard's robots read from a Redis that refuses (as MISCONF does on a full disk)."""
    monkeypatch.setattr(middleware, "_alerted", {})

    def refuse(*args, **kwargs):
        raise redis.exceptions.ResponseError(MISCONF)

    monkeypatch.setattr(snapshots, "robot_rows", refuse)


@pytest.mark.django_db(transaction=True)
def test_a_page_whose_redis_refuses_answers_503_with_the_reason_and_an_alert(refusing, operator, client_for):
    answer = client_for(operator).get("/")
    assert answer.status_code == 503
    assert b"Redis refuses writes: it cannot save its data (disk full under var/?)" in answer.content
    alert = wait_for(lambda: Alert.objects.filter(kind="store_refused").first(), 10, "the alert")
    assert "Redis refuses writes" in alert.message


@pytest.mark.django_db
def test_the_api_says_503_in_json(operator, client_for, monkeypatch):
    from execution.models import Instruction

    def locked(*args, **kwargs):
        raise OperationalError("database is locked")

    monkeypatch.setattr(middleware, "_alert", lambda words: None)
    monkeypatch.setattr(Instruction.objects, "select_related", locked)
    answer = client_for(operator).get("/api/instructions")
    assert answer.status_code == 503
    assert "the database is locked" in answer.json()["detail"]
