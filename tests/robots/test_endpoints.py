"""Where the portal may connect: URL checks, one canonical URL per endpoint, the allow-list and its setting."""

import asyncio

import pytest
from django.core.exceptions import ImproperlyConfigured

from fleet.env import env_int, env_networks
from robots.endpoints import AllowList, EndpointRefused, resolve

LOCAL = AllowList.parse(["127.0.0.0/8", "::1/128", "10.0.0.0/8", "192.168.0.0/16"])


def canonical(url: str, allowed: AllowList = LOCAL) -> str:
    return asyncio.run(resolve(url, allowed))


@pytest.mark.parametrize(
    "alias",
    ["ws://127.0.0.1:9090", "ws://localhost:9090", "ws://LOCALHOST:9090/", "ws://0x7f000001:9090",
     "ws://2130706433:9090", "ws://127.1:9090", "ws://[::ffff:127.0.0.1]:9090"],
)  # fmt: skip
def test_aliases_of_the_loopback_endpoint_are_one_url(alias):
    assert canonical(alias) == "ws://127.0.0.1:9090"


def test_the_port_is_explicit_and_the_path_kept():
    assert canonical("ws://127.0.0.1") == "ws://127.0.0.1:80"
    assert canonical("ws://127.0.0.1:9090/rosbridge/?x=1") == "ws://127.0.0.1:9090/rosbridge?x=1"
    assert canonical("ws://[::1]:9090") == "ws://[::1]:9090"  # a server may listen on one loopback only
    assert canonical("wss://localhost:9443") == "wss://localhost:9443"  # TLS checks the name: kept


@pytest.mark.parametrize(
    ("url", "reason"),
    [
        ("ws://127.0.0.1:99999", "not a valid endpoint URL (the port must be 1-65535)"),
        ("ws://127.0.0.1:0", "not a valid endpoint URL (the port must be 1-65535)"),
        ("http://127.0.0.1:9090", "not a WebSocket URL (expected ws://host:port)"),
        ("ws://:9090", "not a WebSocket URL (expected ws://host:port)"),
        ("9090", "not a WebSocket URL (expected ws://host:port)"),
        ("ws://10.0.0.5:9090/" + "x" * 300, "longer than 255 characters"),
        (
            "ws://8.8.8.8:9090",
            "refused: 8.8.8.8 is outside the allowed robot networks (FLEET_ROBOT_ALLOWED_NETWORKS)",
        ),
        ("ws://0.0.0.0:9090", "refused: 0.0.0.0 is outside the allowed robot networks"),
    ],
)
def test_urls_the_portal_does_not_connect_to_are_refused_with_the_reason(url, reason):
    with pytest.raises(EndpointRefused) as info:
        canonical(url)
    assert reason in str(info.value)


def test_a_refusal_never_repeats_a_password():
    with pytest.raises(EndpointRefused) as info:
        canonical("ws://robot:s3cret@127.0.0.1:9090")
    assert "s3cret" not in str(info.value) and "credentials in the URL are not supported" in str(info.value)


def test_a_host_name_in_the_allow_list_is_trusted_by_name():
    by_name = AllowList.parse(["localhost"])
    assert canonical("ws://localhost:9090", by_name) == "ws://127.0.0.1:9090"
    with pytest.raises(EndpointRefused):
        canonical("ws://127.0.0.1:9090", by_name)


def test_the_settings_read_the_caps_and_the_allow_list_or_name_the_bad_variable(monkeypatch):
    monkeypatch.setenv("FLEET_ROBOT_MAX_FRAME_MB", "lots")
    with pytest.raises(ImproperlyConfigured, match="FLEET_ROBOT_MAX_FRAME_MB: expected a whole number"):
        env_int("FLEET_ROBOT_MAX_FRAME_MB", 16, minimum=1)
    monkeypatch.setenv("FLEET_ROBOT_MAX_FRAME_MB", "0")
    with pytest.raises(ImproperlyConfigured, match="must be at least 1"):
        env_int("FLEET_ROBOT_MAX_FRAME_MB", 16, minimum=1)
    monkeypatch.setenv("FLEET_ROBOT_ALLOWED_NETWORKS", "10.0.0.0/8,robot-1.lan")
    assert env_networks("FLEET_ROBOT_ALLOWED_NETWORKS", []) == ["10.0.0.0/8", "robot-1.lan"]
    monkeypatch.setenv("FLEET_ROBOT_ALLOWED_NETWORKS", "10.0.0.0/8,not a host!")
    with pytest.raises(ImproperlyConfigured, match="FLEET_ROBOT_ALLOWED_NETWORKS: 'not a host!' is neither"):
        env_networks("FLEET_ROBOT_ALLOWED_NETWORKS", [])
