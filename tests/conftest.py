"""Fixtures shared by every app's tests."""

import uuid

import pytest
from django.contrib.auth.models import Group, User

from access.roles import ADMIN, OPERATOR, VIEWER, sync_groups

PASSWORD = "correct-horse-battery"


def pytest_configure(config):
    """A stop socket of this run's own (none listens unless a test starts one): a `make run` on this checkout's
    var folder never gets the tests' stops. Under pytest-xdist each worker has its own database (pytest-django
    suffixes it) and so its own robot ids: its Redis keys, channel groups and robot locks get its own prefix too,
    for it and for the processes its tests start."""
    import os

    from django.conf import settings

    settings.FLEET_STOP_SOCKET = f"/tmp/fleet-test-{os.getpid()}-stop.sock"
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker:
        prefix = f"{settings.CACHES['default'].get('KEY_PREFIX') or 'fleet'}-{worker}"
        settings.CACHES["default"]["KEY_PREFIX"] = prefix
        settings.CHANNEL_LAYERS["default"]["CONFIG"]["prefix"] = f"{prefix}:asgi"
        settings.FLEET_EXEC_KEY_PREFIX = f"{settings.FLEET_EXEC_KEY_PREFIX}-{worker}"
        os.environ["FLEET_REDIS_PREFIX"] = prefix
        os.environ["FLEET_EXEC_KEY_PREFIX"] = settings.FLEET_EXEC_KEY_PREFIX


@pytest.fixture(scope="session")
def django_db_setup(django_db_setup, django_db_blocker):
    """pytest-django's test database, whose drop at the end is not refused for sessions other threads still hold.

    Server threads (the live portal's, the execution runners') keep their connections open (CONN_MAX_AGE);
    PostgreSQL will not drop a database anyone is connected to, so they are ended first.
    """
    yield
    from django.db import connection

    if connection.vendor == "postgresql":
        with django_db_blocker.unblock(), connection.cursor() as cursor:
            cursor.execute(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
                " WHERE datname = current_database() AND pid <> pg_backend_pid()"
            )


@pytest.fixture
def roles(db):
    """The viewer, operator and admin groups with their permissions."""
    sync_groups()
    return {name: Group.objects.get(name=name) for name in (VIEWER, OPERATOR, ADMIN)}


def _user(roles, name: str, role: str | None, **extra) -> User:
    user = User.objects.create_user(name, password=PASSWORD, **extra)
    if role:
        user.groups.add(roles[role])
    return user


@pytest.fixture
def viewer(roles):
    """A user who may only look."""
    return _user(roles, "vera", VIEWER)


@pytest.fixture
def operator(roles):
    """A user who may instruct and control robots."""
    return _user(roles, "otto", OPERATOR)


@pytest.fixture
def second_operator(roles):
    """Another operator, to contend for control of a robot."""
    return _user(roles, "olga", OPERATOR)


@pytest.fixture
def fleet_admin(roles):
    """A user in the admin group (also Django staff, so the admin site opens)."""
    return _user(roles, "ada", ADMIN, is_staff=True, is_superuser=True)


@pytest.fixture
def client_for(client):
    """Log the test client in as the given user and return it."""

    def _login(user):
        client.force_login(user)
        return client

    return _login


@pytest.fixture
def exec_settings(settings):
    """Redis keys of our own (locks, flags, the executors' membership and wake-ups)."""
    settings.FLEET_EXEC_KEY_PREFIX = f"test:exec:{uuid.uuid4().hex[:8]}"
    return settings


@pytest.fixture
def executor(exec_settings, transactional_db):
    """The executor (execution/executor.py), its loop on a thread of this process: the one that runs what
    dispatch wakes, as `manage.py executor` does. Stopped before the database is emptied."""
    from execution import executor as executors

    with executors.in_thread() as running:
        yield running


@pytest.fixture
def eager_celery(monkeypatch):
    """Celery tasks run at once in the caller (what a worker would do with them)."""
    from fleet.celery import app

    monkeypatch.setitem(app.conf, "task_always_eager", True)
    monkeypatch.setitem(app.conf, "task_eager_propagates", True)


@pytest.fixture(autouse=True)
def fresh_channel_layer():
    """Give every test its own channel layer instance.

    channels-redis binds receive() to the event loop that first used it; a test that served WebSockets from
    another loop (a live server thread) would otherwise leave the process's layer bound to a dead loop.
    """
    from channels.layers import channel_layers

    channel_layers.backends.clear()
    yield
    channel_layers.backends.clear()


def seed_ontology() -> None:
    """The interpreter's seed terms, where they are missing: the migration wrote them, but a transactional test
    flushes every table at its end, so a test that a transactional one ran before in the same process (which
    one does depends on the order, and under pytest-xdist on the worker) finds none."""
    import importlib

    from django.apps import apps

    from interpreter import versions

    importlib.import_module("interpreter.migrations.0002_seed_terms").seed(apps, None)
    versions.bump_ontology()


@pytest.fixture
def seeded_ontology(transactional_db):
    """The interpreter's seed terms, for a transactional test (seed_ontology)."""
    seed_ontology()
