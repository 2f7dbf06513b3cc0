"""brief_lock_wait: a stop's writes wait briefly for a locked database (SQLite or PostgreSQL), inside or outside
a transaction, and the failure reads as the database being locked."""

from __future__ import annotations

import time

import pytest
from django.db import connection, transaction

from execution.bookkeeping import brief_lock_wait
from fleetcore import faults
from robots.models import Robot
from tests.execution.faults import DatabaseLock

SHOW = {
    "sqlite": "PRAGMA busy_timeout",
    "postgresql": "SELECT current_setting('lock_timeout')",
}


def wait_setting():
    with connection.cursor() as cursor:
        cursor.execute(SHOW[connection.vendor])
        return cursor.fetchone()[0]


@pytest.mark.django_db  # inside the test's transaction
def test_the_wait_is_shortened_for_the_block_and_restored_inside_a_transaction():
    before = wait_setting()
    with brief_lock_wait(0.25):
        assert str(wait_setting()) in ("250", "250ms")
    assert wait_setting() == before


@pytest.mark.django_db(transaction=True)
def test_a_locked_database_fails_the_write_within_the_bound_as_locked():
    Robot.objects.create(name="r1", endpoint="ws://127.0.0.1:1")
    lock = DatabaseLock(connection.settings_dict)
    before = wait_setting()  # outside any transaction (autocommit)
    try:
        lock.take()
        started = time.monotonic()
        with pytest.raises(Exception) as raised, brief_lock_wait(0.25), transaction.atomic():
            Robot.objects.filter(name="r1").update(endpoint="ws://127.0.0.1:2")
        waited = time.monotonic() - started
    finally:
        lock.close()
    assert faults.store_fault(raised.value) == "the database is locked (another writer holds it)"
    assert waited < 15  # bounded by the brief wait, not SQLite's 20 s or PostgreSQL's none (generous: load)
    assert wait_setting() == before
    assert Robot.objects.get(name="r1").endpoint == "ws://127.0.0.1:1"
