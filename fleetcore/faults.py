"""What a failure of a store means, in a person's words: Redis or the database away, frozen or refusing writes.

One place for the words, so a stop's answer ("stopped; could not record it: Redis refuses writes ...") and a
page's 503 say the same thing. Plain: exceptions are told apart by their class's module and name and by their
text (redis-py's, Django's, sqlite3's and psycopg's), so nothing here imports them.
"""

from __future__ import annotations

import errno

DISK_FULL = "disk full under var/?"

_REDIS_REFUSALS = (
    ("MISCONF", f"Redis refuses writes: it cannot save its data ({DISK_FULL})"),
    ("NOREPLICAS", "Redis refuses writes: not enough replicas"),
    ("READONLY", "Redis refuses writes: it is a read-only replica"),
    ("OOM", "Redis refuses writes: out of memory"),
)
_DATABASE_REFUSALS = (
    ("database is locked", "the database is locked (another writer holds it)"),
    ("database table is locked", "the database is locked (another writer holds it)"),
    ("lock timeout", "the database is locked (another writer holds it)"),  # PostgreSQL's lock_timeout
    ("database or disk is full", f"the database refuses writes: {DISK_FULL}"),
    ("no space left", f"the database refuses writes: {DISK_FULL}"),
    ("disk i/o error", f"the database cannot write to disk ({DISK_FULL})"),
    ("readonly database", "the database refuses writes (read-only)"),
    ("read-only", "the database refuses writes (read-only)"),
)


def _chain(exc: BaseException):
    """The exception and those it was raised from or during, outermost first."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        yield exc
        exc = exc.__cause__ or exc.__context__


def _redis_words(exc: BaseException) -> str | None:
    name, text = type(exc).__name__, str(exc)
    for code, words in _REDIS_REFUSALS:
        if text.startswith(code) or f" {code} " in f" {text} ":
            return words
    if name == "TimeoutError":
        return "Redis does not answer (frozen or overloaded)"
    if name in ("ConnectionError", "BusyLoadingError", "AuthenticationError"):
        return "Redis unavailable"
    return None


def _database_words(exc: BaseException) -> str | None:
    text = str(exc).lower()
    for needle, words in _DATABASE_REFUSALS:
        if needle in text:
            return words
    if type(exc).__name__ in ("OperationalError", "InterfaceError"):
        return "the database is unavailable"
    return None


def store_fault(exc: BaseException) -> str | None:
    """The words for an exception that means Redis or the database is away or refuses writes; None otherwise."""
    for link in _chain(exc):
        module = type(link).__module__ or ""
        words = None
        if module.startswith("redis"):
            words = _redis_words(link)
        elif module.startswith(("django.db", "sqlite3", "psycopg")):
            words = _database_words(link)
        elif isinstance(link, OSError) and link.errno == errno.ENOSPC:
            words = f"a write failed: {DISK_FULL}"
        if words:
            return words
    return None


def in_words(exc: BaseException, store: str) -> str:
    """store_fault's words, or "<store> unavailable (<the exception's class>)" for a failure it does not know."""
    if isinstance(exc, TimeoutError) and store == "Redis":
        return "Redis does not answer (frozen or overloaded)"
    return store_fault(exc) or f"{store} unavailable ({type(exc).__name__})"


def refusal(exc: BaseException) -> str | None:
    """store_fault's words when the store answers but refuses writes (a full disk, a locked database, a read-only
    replica); None when it is away or frozen, or the failure is no store's."""
    words = store_fault(exc)
    refused = {text for _, text in (*_REDIS_REFUSALS, *_DATABASE_REFUSALS)} | {f"a write failed: {DISK_FULL}"}
    return words if words in refused or (words or "").startswith("the database cannot write") else None
