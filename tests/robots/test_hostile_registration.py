"""Registration against hostile endpoints: each gets its own result, the good ones register, nothing is lost."""

import json
from io import StringIO

import pytest
from django.core.management import CommandError, call_command

from robots.models import RegistrationRecord, Robot
from robots.registration import register_endpoints
from tests.robots.fakes import HostileEndpoint, answer, fragmented, free_port, hostile_urdf, with_id

pytestmark = [pytest.mark.timeout(60), pytest.mark.django_db]

MB = 1024 * 1024


def by_url(results) -> dict:
    return {r.url: r for r in results}


def test_a_batch_of_hostile_endpoints_registers_the_good_one_and_refuses_each_other_with_its_reason(
    endpoint, settings
):
    settings.FLEET_ROBOT_MAX_FRAME_MB = 2
    settings.FLEET_ROBOT_MAX_URDF_MB = 1
    settings.FLEET_ROBOT_MAX_TOPICS = 50
    good = endpoint()
    id_list = with_id(lambda i: {"op": "service_response", "id": [i], "values": {}, "result": True})
    hostile = {
        "nodes": HostileEndpoint("n", nodes=answer({"nodes": 5})),
        "id": HostileEndpoint("i", node_details=id_list),
        "fragment": HostileEndpoint("f", topics=fragmented({"topics": [], "types": []}, total="abc")),
        "urdf": HostileEndpoint("u", urdf=hostile_urdf("u", size=int(1.5 * MB))),
        "frame": HostileEndpoint("fr", get_param=answer({"value": "x" * (3 * MB)})),
        "topics": HostileEndpoint("t", extra_topics=60),
        "long": HostileEndpoint("l", nodes=answer({"nodes": ["/" + "n" * 300]})),
    }
    bad_port = "ws://127.0.0.1:99999"
    for ep in hostile.values():
        ep.__enter__()
    try:
        urls = [good.url, *(ep.url for ep in hostile.values()), bad_port]
        results = by_url(register_endpoints(urls, call_timeout=0.5))
    finally:
        for ep in hostile.values():
            ep.__exit__(None, None, None)
    error = {key: results[ep.url].error for key, ep in hostile.items()}
    assert results[good.url].ok and results[good.url].robots == ["fakebot"]
    assert error["nodes"].endswith(
        "/rosapi/nodes answered 'nodes' = '5', not a list of names (text up to 255 characters)"
    )
    assert "only bad frames within 0.5 s of calling /rosapi/node_details (1 dropped)" in error["id"]
    assert "answered a bad frame (fragment with 'total' = 'abc')" in error["fragment"]
    assert "/robot_description is 1.5 MB, more than the 1 MB limit (FLEET_ROBOT_MAX_URDF_MB)" in error["urdf"]
    assert "larger than the 2 MB limit (FLEET_ROBOT_MAX_FRAME_MB)" in error["frame"]
    assert "lists 62 topics, more than the limit of 50 (FLEET_ROBOT_MAX_TOPICS)" in error["topics"]
    assert "not a list of names (text up to 255 characters)" in error["long"]
    assert results[bad_port].error == f"{bad_port}: not a valid endpoint URL (the port must be 1-65535)"
    for result in results.values():
        assert "\n" not in result.error and len(result.error) < 400
    assert not results[bad_port].ok and all(not results[ep.url].ok for ep in hostile.values())
    assert list(Robot.objects.values_list("name", flat=True)) == ["fakebot"]
    records = RegistrationRecord.objects.filter(finished_at__isnull=False)
    assert records.count() == len(urls) and records.filter(ok=False).count() == len(urls) - 1


def test_the_good_robot_registered_in_a_hostile_batch_is_driven_like_any_other(endpoint):
    """Registration keeps the good endpoint's bindings whole: its move topic reaches the robot's driver."""
    good = endpoint()
    with HostileEndpoint("n", nodes=answer({"nodes": 5})) as bad:
        register_endpoints([bad.url, good.url], call_timeout=0.5)
    robot = Robot.objects.get(name="fakebot")
    move = robot.bindings.get(action="move")
    assert (move.target, move.message_type) == ("/cmd_vel", "geometry_msgs/Twist")
    assert robot.endpoint == good.url and robot.wheel_count == 2


def test_a_host_outside_the_allowed_networks_is_refused_before_anything_connects(endpoint, settings):
    ep = endpoint()
    settings.FLEET_ROBOT_ALLOWED_NETWORKS = ["10.0.0.0/8"]
    with HostileEndpoint() as hostile:
        (result, other) = register_endpoints([ep.url, hostile.url])
        assert hostile.connections == 0
    assert result.error == (
        f"{ep.url}: refused: 127.0.0.1 is outside the allowed robot networks (FLEET_ROBOT_ALLOWED_NETWORKS)"
    )
    assert not other.ok and not Robot.objects.exists()


def test_by_default_only_loopback_and_private_networks_are_allowed():
    port = free_port()
    results = by_url(register_endpoints([f"ws://0.0.0.0:{port}", f"ws://169.254.169.254:{port}"]))
    for url, result in results.items():
        assert "is outside the allowed robot networks (FLEET_ROBOT_ALLOWED_NETWORKS)" in result.error, url


def test_aliases_of_one_endpoint_register_one_robot_stored_under_its_address(endpoint):
    ep = endpoint()
    aliases = [ep.url, f"ws://localhost:{ep.port}", f"ws://0x7f000001:{ep.port}", f"ws://127.1:{ep.port}/"]
    results = register_endpoints(aliases)
    assert [r.robots for r in results] == [["fakebot"]] * 4
    assert all(r.ok and r.endpoint == ep.url for r in results)
    register_endpoints([f"ws://LOCALHOST:{ep.port}"])  # later, under yet another name: the same robot again
    robot = Robot.objects.get()
    assert (robot.name, robot.endpoint) == ("fakebot", ep.url)


def test_unreachable_endpoints_do_not_say_which_ports_are_open(endpoint):
    with HostileEndpoint(topics=lambda call: []) as silent:  # a WebSocket server that never answers
        closed = free_port()  # picked while the silent one holds its port: never the same one (it was, once)
        results = register_endpoints([f"ws://127.0.0.1:{closed}", silent.url], call_timeout=0.3)
    assert [r.error.split(": ", 1)[1] for r in results] == ["unreachable (no rosbridge server answered)"] * 2


def test_register_command_registers_the_good_robot_and_prints_an_error_for_each_bad_one(endpoint):
    good = endpoint()
    out, err = StringIO(), StringIO()
    with (
        HostileEndpoint("n", nodes=answer({"nodes": 5})) as nodes,
        HostileEndpoint("f", topics=fragmented({"topics": []}, total="abc")) as fragment,
    ):
        bad = [nodes.url, fragment.url, "ws://127.0.0.1:99999", "http://example"]
        with pytest.raises(CommandError, match="4 of 5 endpoints failed"):
            call_command("register", "--json", good.url, *bad, "--timeout", "0.5", stdout=out, stderr=err)
    (robot,) = json.loads(out.getvalue())
    assert robot["name"] == "fakebot" and robot["bindings"]["move"]["topic"] == "/cmd_vel"
    lines = err.getvalue().splitlines()
    assert len(lines) == 4
    for url, line in zip(bad, lines, strict=True):
        assert line.startswith(f"error: {url}: ")


def test_a_background_registration_is_queryable_from_the_moment_it_is_queued(
    endpoint, client_for, fleet_admin, eager_celery
):
    good = endpoint()
    bad = "ws://127.0.0.1:99999"
    reply = client_for(fleet_admin).post(
        "/api/robots/register", {"endpoints": [good.url, bad]}, content_type="application/json"
    )
    assert reply.status_code == 202
    records = {r["url"]: r["record"] for r in reply.json()["records"]}
    assert set(records) == {good.url, bad}
    found = {
        url: client_for(fleet_admin).get(f"/api/robots/registrations/{pk}").json()
        for url, pk in records.items()
    }
    assert found[good.url]["ok"] and found[good.url]["robots"] == ["fakebot"]
    assert found[good.url]["finished_at"] is not None
    assert not found[bad]["ok"] and "the port must be 1-65535" in found[bad]["error"]


def test_a_queued_registration_that_no_worker_ran_yet_reads_as_running(
    endpoint, client_for, fleet_admin, monkeypatch
):
    from robots import tasks

    monkeypatch.setattr(tasks.register_endpoints, "delay", lambda *args: type("Task", (), {"id": "t1"})())
    reply = client_for(fleet_admin).post(
        "/api/robots/register", {"endpoints": [endpoint().url]}, content_type="application/json"
    )
    (ref,) = reply.json()["records"]
    record = client_for(fleet_admin).get(f"/api/robots/registrations/{ref['record']}").json()
    assert (record["finished_at"], record["ok"], record["error"]) == (None, False, "")


def test_a_registration_that_stops_on_its_own_error_leaves_no_record_running(endpoint, monkeypatch):
    from robots import registration

    def broken(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(registration, "store_all", broken)
    with pytest.raises(RuntimeError):
        register_endpoints([endpoint().url])
    (record,) = RegistrationRecord.objects.all()
    assert record.finished_at is not None and record.error == "registration stopped unexpectedly"
