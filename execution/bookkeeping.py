"""How long a stop's bookkeeping waits for a locked database: briefly, so the stop's answer comes within a bound."""

from __future__ import annotations

import contextlib
import logging

from django.db import connection

log = logging.getLogger(__name__)

STOP_LOCK_WAIT_S = (
    1.0  # a stop's writes wait this long for a locked database (SQLite: 20 s, PostgreSQL: for ever)
)


@contextlib.contextmanager
def brief_lock_wait(seconds: float = STOP_LOCK_WAIT_S):
    """Within this block, writes wait `seconds` at most for another writer's lock (SQLite's busy_timeout,
    PostgreSQL's lock_timeout): a stop's answer comes within a bound while the database is locked. The setting
    is restored after the block; on PostgreSQL a transaction that fails reverts it by itself."""
    setting = _SETTINGS.get(connection.vendor)
    before = None
    try:
        if setting is not None:
            with connection.cursor() as cursor:
                before = setting(cursor, None)
                setting(cursor, int(seconds * 1000))
    except Exception:  # no database at all: the writes fail on their own, said by the stop
        log.warning("could not shorten the database's lock wait", exc_info=True)
    try:
        yield
    finally:
        if before is not None:
            with contextlib.suppress(Exception), connection.cursor() as cursor:
                setting(cursor, before)


def _sqlite_wait(cursor, value):
    """Set busy_timeout to value (ms) or, with None, read it."""
    if value is None:
        return cursor.execute("PRAGMA busy_timeout").fetchone()[0]
    cursor.execute(f"PRAGMA busy_timeout = {int(value)}")
    return value


def _postgresql_wait(cursor, value):
    """Set lock_timeout (for the session; a bare number is ms, else as read) or, with None, read it."""
    if value is None:
        cursor.execute("SELECT current_setting('lock_timeout')")
        return cursor.fetchone()[0]
    cursor.execute("SELECT set_config('lock_timeout', %s, false)", [str(value)])
    return value


_SETTINGS = {"sqlite": _sqlite_wait, "postgresql": _postgresql_wait}
