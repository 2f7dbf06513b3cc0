"""Version tokens of the ontology and of the fleet, shared by every process through the cache (Redis).

The ontology's number lives in the database (OntologyVersion) and its token in the cache; the fleet's token
only in the cache (a missing token just makes every process reload once). Tokens are random, so two
databases sharing one Redis never mistake each other's versions for their own.
"""

import uuid

from django.core.cache import cache
from django.db import transaction
from django.db.models import F
from django.utils import timezone

from interpreter.models import OntologyVersion

ONTOLOGY_KEY = "interpreter:ontology-token"
FLEET_KEY = "interpreter:fleet-token"
TIMEOUT = None  # never expire
# Changes made in this process, seen by its own store (interpreter.service.Store) before they reach the cache.
LOCAL_CHANGES: list[str] = []


def _token() -> str:
    return uuid.uuid4().hex


def bump_ontology() -> str:
    """Record an edit: a new number and token in the DB now, in the cache after commit."""
    token = _token()
    updated = OntologyVersion.objects.filter(pk=1).update(
        number=F("number") + 1, token=token, changed_at=timezone.now()
    )
    if not updated:
        OntologyVersion.objects.update_or_create(pk=1, defaults={"number": 1, "token": token})
    LOCAL_CHANGES.append("ontology")
    transaction.on_commit(lambda: cache.set(ONTOLOGY_KEY, token, TIMEOUT))
    return token


def bump_fleet() -> str:
    """Record a change of robots or locations."""
    token = _token()
    LOCAL_CHANGES.append("fleet")
    transaction.on_commit(lambda: cache.set(FLEET_KEY, token, TIMEOUT))
    return token


def current() -> tuple[str, str]:
    """Return (ontology token, fleet token), one cache round trip in the common case."""
    found = cache.get_many([ONTOLOGY_KEY, FLEET_KEY])
    onto, fleet = found.get(ONTOLOGY_KEY), found.get(FLEET_KEY)
    if onto is None:
        onto = _ontology_token_from_db()
        cache.set(ONTOLOGY_KEY, onto, TIMEOUT)
    if fleet is None:
        fleet = _token()
        cache.add(FLEET_KEY, fleet, TIMEOUT)
        fleet = cache.get(FLEET_KEY) or fleet
    return onto, fleet


def ontology_number() -> int:
    row = OntologyVersion.objects.filter(pk=1).first()
    return row.number if row else 0


def _ontology_token_from_db() -> str:
    row = OntologyVersion.objects.filter(pk=1).first()
    return row.token if row and row.token else "db-empty"
