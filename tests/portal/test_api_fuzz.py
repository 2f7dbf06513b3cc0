"""The JSON API under schemathesis: generated calls from its own OpenAPI document, as each role, against the WSGI app.

For every operation, valid and invalid data (schemathesis's positive and negative modes), a bounded number of
examples per operation and role (FUZZ_EXAMPLES): no answer is a 5xx, and every 4xx says what was wrong: 401/403
name the ability (access.roles), 404 and 422 the field. On SQLite by default, on PostgreSQL in CI (NUL characters,
huge numbers, aware and naive times, whitespace-only text: what the two databases disagree on).
Side effects stay inside the test: registration is recorded, not run; stops reach no robot (execution.control is a
recorder); queued instructions are never launched (this test's transaction never commits).
"""

import re

import pytest
import schemathesis
from django.contrib.auth.models import Group, User
from django.core import signals
from django.core.wsgi import get_wsgi_application
from django.db import close_old_connections
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from access.roles import ADMIN, OPERATOR, VIEWER, sync_groups
from execution.models import Instruction
from portal.api import api

FUZZ_EXAMPLES = 30  # per operation and role: 14 operations x 4 callers x 30, about a minute on one core
CALLERS = (None, VIEWER, OPERATOR, ADMIN)
CSRF = "f" * 32  # a CSRF cookie and header that match, as the portal's pages send them
SCHEMA = schemathesis.openapi.from_dict(api.get_openapi_schema())
SCHEMA.app = get_wsgi_application()


@pytest.fixture
def wsgi_in_test_transaction():
    """Requests served in this thread keep the test's connection and transaction, as Django's test client does."""
    signals.request_started.disconnect(close_old_connections)
    signals.request_finished.disconnect(close_old_connections)
    yield
    signals.request_started.connect(close_old_connections)
    signals.request_finished.connect(close_old_connections)


@pytest.fixture
def recorded_registration(monkeypatch):
    """robots.tasks.register_endpoints recorded: the fuzzer's URLs are never connected to."""
    calls = []

    class Registration:
        def __call__(self, urls, user_id, record_ids=None):
            calls.append(urls)
            return []

        def delay(self, urls, user_id, record_ids=None):
            calls.append(urls)
            return type("Queued", (), {"id": "recorded"})()

    monkeypatch.setattr("robots.tasks.register_endpoints", Registration())
    return calls


def _session_cookies(role) -> dict:
    from django.test import Client

    cookies = {"csrftoken": CSRF}
    if role is None:
        return cookies
    sync_groups()
    user = User.objects.create_user(f"fuzz-{role}", password="x" * 12)
    user.groups.add(Group.objects.get(name=role))
    client = Client()
    client.force_login(user)
    return {**cookies, "sessionid": client.cookies["sessionid"].value}


FIELD_FIRST = re.compile(r"^[\w.\[\]]+: \S")


def _says_what_was_wrong(status: int, body) -> str | None:
    """None if a 4xx answer says what was wrong, else why not."""
    detail = body.get("detail") if isinstance(body, dict) else None
    if status == 401:
        return None if detail else "401 without a detail"
    if status == 403:
        return None if isinstance(detail, str) and re.search(r"\(\w+\)", detail) else "403 names no ability"
    if isinstance(detail, list):
        unnamed = [error for error in detail if len(error.get("loc", [])) < 2 or not error.get("msg")]
        return None if detail and not unnamed else f"errors without a field: {unnamed or detail}"
    if isinstance(detail, str) and FIELD_FIRST.match(detail):
        return None
    return f"{status} detail names no field: {detail!r}"


def _known_rows(case, world, use_them: bool) -> None:
    """On half the examples, the names and ids in the call are the world's real rows: the other fields then
    reach the database (a slot with an aware time for a real robot, not just "no robot named 'x'")."""
    if not use_them:
        return
    known = {
        "robot": world["robot"].name,
        "name": world["robot"].name,
        "goal": world["location"].name,
        "slot_id": world["slot"].pk,
        "instruction_id": world["instruction"].pk,
        "location": world["location"].pk,
    }
    for where in (case.path_parameters, case.body):
        if isinstance(where, dict):
            for key in where.keys() & known.keys():
                where[key] = known[key]


def _fuzz(operation, cookies: dict, world) -> None:
    @settings(
        max_examples=FUZZ_EXAMPLES,
        deadline=None,
        database=None,
        derandomize=True,  # the same calls on every run: a failure here is a failure in CI
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(case=operation.as_strategy(), use_known=st.booleans())
    def run(case, use_known):
        _known_rows(case, world, use_known)
        response = case.call(headers={"X-CSRFToken": CSRF}, cookies=cookies)
        call = f"{case.method} {case.formatted_path} body={case.body!r} query={case.query!r}"
        assert response.status_code < 500, f"{call} -> {response.status_code}: {response.text[:500]}"
        if response.status_code >= 400:
            try:
                body = response.json()
            except ValueError:
                body = None
            why = _says_what_was_wrong(response.status_code, body)
            assert why is None, f"{call} -> {why}"

    run()


@pytest.mark.slow
@pytest.mark.timeout(240)
@pytest.mark.parametrize("role", CALLERS, ids=lambda role: role or "anonymous")
def test_generated_calls_never_get_a_5xx_and_every_4xx_names_the_field(
    role, world, seeded_words, recorded_control, recorded_registration, wsgi_in_test_transaction, settings
):
    settings.FLEET_EXEC_KEY_PREFIX = "test:fuzz"  # a stop's flags land nowhere a real runner reads
    cookies = _session_cookies(role)
    world["instruction"] = Instruction.objects.create(text="move probe to A", source="api")
    operations = [result.ok() for result in SCHEMA.get_all_operations()]
    assert len(operations) >= 14
    for operation in operations:
        _fuzz(operation, cookies, world)
    if role in (None, VIEWER):
        assert recorded_control == [] and recorded_registration == []  # refused before anything ran
