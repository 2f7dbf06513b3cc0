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

ONTOLOGY_KEY = "interpreter:ontology-token"
FLEET_KEY = "interpreter:fleet-token"
TIMEOUT = None  # never expire


def _token() -> str:
    return uuid.uuid4().hex


def bump_ontology() -> str:
    """Record an edit: a new number and token in the DB now, in the cache after commit."""
    from interpreter.models import OntologyVersion

    token = _token()
    updated = OntologyVersion.objects.filter(pk=1).update(
        number=F("number") + 1, token=token, changed_at=timezone.now()
    )
    if not updated:
        OntologyVersion.objects.update_or_create(pk=1, defaults={"number": 1, "token": token})
    _local_changes().append("ontology")
    transaction.on_commit(lambda: cache.set(ONTOLOGY_KEY, token, TIMEOUT))
    return token


def bump_fleet() -> str:
    """Record a change of robots or locations."""
    token = _token()
    _local_changes().append("fleet")
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
    from interpreter.models import OntologyVersion

    row = OntologyVersion.objects.filter(pk=1).first()
    return row.number if row else 0


def _ontology_token_from_db() -> str:
    from interpreter.models import OntologyVersion

    row = OntologyVersion.objects.filter(pk=1).first()
    return row.token if row and row.token else "db-empty"


def _local_changes() -> list:
    """Changes made in this process, seen by its own store before they reach the cache."""
    from interpreter.service import store

    return store().local_changes
