"""Pages show stored details as words: the audit trail's details, the schedules' help with slots turned off."""

import pytest

from audit.records import record
from execution.models import TimeSlot
from portal.templatetags.fleet_format import readable


def test_readable_values():
    assert readable(["robot1", "husky"]) == "robot1, husky"
    assert readable({"robot1": "stopped", "ok": True}) == "robot1: stopped; ok: yes"
    assert readable("") == "–" and readable(None) == "–" and readable([]) == "–"
    assert readable(0.5) == "0.5" and readable(3) == "3"


@pytest.mark.django_db
def test_audit_details_are_not_python(client_for, fleet_admin):
    record(fleet_admin, "register", "ws://x", ok=False, robots=["a", "b"], error="", taken_over_from=None)
    page = client_for(fleet_admin).get("/audit/").content.decode()
    assert "robots:</span> a, b" in page and "taken over from:</span> –" in page and "ok:</span> no" in page
    assert "[&#x27;a&#x27;" not in page and "None" not in page and "False" not in page


@pytest.mark.django_db
def test_schedules_say_how_to_enable_slots_that_are_off(client_for, fleet_admin, fleet):
    client = client_for(fleet_admin)
    assert "slots-off-help" not in client.get("/schedules/").content.decode()  # every slot is on
    TimeSlot.objects.update(enabled=False)
    page = client.get("/schedules/").content.decode()
    assert (
        "slots-off-help" in page
        and "FLEET_DEMO_SCHEDULES=1" in page
        and "tick <strong>enabled</strong>" in page
    )


@pytest.mark.django_db
def test_registration_prefill_lists_every_simulated_endpoint(client_for, fleet_admin, settings):
    from fleetcore.world import load_world

    settings.FLEET_SIM_PORT_BASE = 9190
    page = client_for(fleet_admin).get("/register/").content.decode()
    world = load_world(settings.FLEET_WORLD)
    used = {robot.endpoint for robot in world.robots}
    for endpoint in world.endpoints:
        url = f"ws://127.0.0.1:{9190 + endpoint.port_offset}"
        assert (url in page) == (endpoint.key in used), url
