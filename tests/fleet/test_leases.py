"""Control leases: one holder at a time, expiry, admin takeover, viewers never command."""

from datetime import timedelta

import pytest
from django.utils import timezone

from access import leases
from access.models import ControlLease
from audit.models import AuditEntry
from robots.models import Robot


@pytest.fixture
def husky(db):
    return Robot.objects.create(name="husky", endpoint="ws://127.0.0.1:9092")


def test_second_operator_is_refused_while_first_holds(husky, operator, second_operator):
    leases.take(operator, husky)
    leases.check_command(operator, husky)
    with pytest.raises(leases.ControlRefused, match="held by otto"):
        leases.check_command(second_operator, husky)
    with pytest.raises(leases.ControlRefused, match="held by otto"):
        leases.take(second_operator, husky)


def test_expired_lease_frees_the_robot(husky, operator, second_operator):
    leases.take(operator, husky)
    ControlLease.objects.update(expires_at=timezone.now() - timedelta(seconds=1))
    leases.check_command(second_operator, husky)
    assert leases.take(second_operator, husky).user == second_operator


def test_admin_takes_over_and_it_is_audited(husky, operator, fleet_admin):
    leases.take(operator, husky)
    leases.take(fleet_admin, husky)
    assert leases.holder(husky) == fleet_admin
    entry = AuditEntry.objects.filter(action="control.take", user=fleet_admin).get()
    assert entry.details["taken_over_from"] == "otto"


def test_viewer_never_commands(husky, viewer):
    with pytest.raises(leases.ControlRefused, match="only view"):
        leases.check_command(viewer, husky)
    with pytest.raises(leases.ControlRefused):
        leases.take(viewer, husky)


def test_only_holder_or_admin_releases(husky, operator, second_operator, fleet_admin):
    leases.take(operator, husky)
    with pytest.raises(leases.ControlRefused):
        leases.release(second_operator, husky)
    assert leases.release(fleet_admin, husky) is True
    assert leases.holder(husky) is None


def test_holders_names_each_robots_holder_and_reads_no_user_for_the_callers_own_leases(
    husky, operator, second_operator, django_assert_num_queries
):
    """A teleop re-check reads a fleet's holders every half second: the presser's own leases build no user row."""
    tiago = Robot.objects.create(name="tiago", endpoint="ws://127.0.0.1:9093")
    free = Robot.objects.create(name="free", endpoint="ws://127.0.0.1:9094")
    gone = Robot.objects.create(name="gone", endpoint="ws://127.0.0.1:9095")
    leases.take(operator, husky)
    leases.take(second_operator, tiago)
    leases.take(operator, gone)
    ControlLease.objects.filter(robot=gone).update(expires_at=timezone.now() - timedelta(seconds=1))
    ids = [husky.pk, tiago.pk, free.pk, gone.pk]
    with django_assert_num_queries(2):  # the leases' ids, then the one other holder
        held = leases.holders(ids, operator)
    assert held == {husky.pk: operator, tiago.pk: second_operator}
    assert held[husky.pk] is operator and held[tiago.pk].username == "olga"
    with django_assert_num_queries(1):
        assert leases.holders([husky.pk, free.pk], operator) == {husky.pk: operator}
    assert leases.holders(ids) == {husky.pk: operator, tiago.pk: second_operator}


def test_an_instruction_to_many_robots_checks_their_leases_in_one_query(
    operator, second_operator, django_assert_num_queries
):
    """The access check of an instruction to 50 robots read each robot's lease apart (a POST of 2 s on the
    cluster): one query for all of them now, refusing as before when someone else holds one."""
    from execution import dispatch

    robots = [
        Robot.objects.create(name=f"r{i}", endpoint="ws://127.0.0.1:1", namespace=f"/r{i}") for i in range(6)
    ]
    leases.take(operator, robots[0])  # the operator's own lease does not refuse them
    with django_assert_num_queries(1):
        dispatch._check_access(robots, operator, "api")
    leases.take(second_operator, robots[4])
    with pytest.raises(dispatch.Refused, match="r4 is held by"):
        dispatch._check_access(robots, operator, "api")
