"""What a browser sends over a page's socket: every malformed, unknown or excessive message is answered in words,
the socket stays open, and no raw database error or traceback reaches the page (portal.socket_input)."""

import functools
import json

import pytest
from asgiref.sync import sync_to_async
from channels.testing import WebsocketCommunicator
from django.db import OperationalError

import execution.control
from portal import socket_input
from portal.socket_input import BadFrame, RateLimiter, decode

# --- the decoder and the limiter alone --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "binary", "says"),
    [
        (None, b"\x00\x01", "frame: binary frames are not accepted"),
        ("{not json", None, "frame: not valid JSON"),
        ("[" * 5000 + "]" * 5000, None, "frame: not valid JSON"),  # deeper than json's own recursion limit
        (json.dumps({"command": "stop", "robots": [[[[[[[[[[1]]]]]]]]]]}), None, "frame: nested deeper"),
        ("5", None, "frame: a JSON object is expected"),
        ("x" * (socket_input.MAX_FRAME_CHARS + 1), None, "frame: longer than"),
    ],
    ids=["binary", "malformed", "deep-array", "deep-object", "not-an-object", "huge"],
)
def test_a_frame_the_portal_does_not_accept_is_named(text, binary, says):
    with pytest.raises(BadFrame, match=says):
        decode(text, binary)


@pytest.mark.parametrize("value", [10**30, 0, -1, True, 1.5, "3", [1], None])
def test_a_robot_id_is_a_whole_number_a_database_holds(value):
    with pytest.raises(BadFrame, match="robot: give one robot id"):
        socket_input.robot_id(value)


def test_a_stuck_key_spends_only_its_own_budget():
    now = [100.0]
    limiter = RateLimiter(rate=20, burst=20, clock=lambda: now[0])
    stuck = ("teleop", 1)
    assert sum(limiter.allow(stuck) for _ in range(100)) == 20
    assert limiter.allow(("stop",)) and limiter.allow(("teleop", 2))  # others still get through
    assert limiter.warn(stuck) and not limiter.warn(stuck)  # told once ...
    now[0] += 1.0
    assert limiter.warn(stuck)  # ... a second
    assert sum(limiter.allow(stuck) for _ in range(100)) == 20  # the budget came back at its rate


def test_the_socket_as_a_whole_has_a_ceiling():
    limiter = RateLimiter(rate=20, burst=20, socket_rate=50, clock=lambda: 7.0)
    passed = sum(limiter.allow(("teleop", robot)) for robot in range(1, 11) for _ in range(10))
    assert passed == 50


# --- over a real socket -----------------------------------------------------------------------------------------


@sync_to_async
def _session_cookie(user) -> bytes:
    from django.test import Client

    client = Client()
    client.force_login(user)
    return f"sessionid={client.cookies['sessionid'].value}".encode()


async def _socket(user):
    from fleet.asgi import application

    headers = [(b"origin", b"http://127.0.0.1"), (b"cookie", await _session_cookie(user))]
    communicator = WebsocketCommunicator(application, "/ws/fleet/", headers=headers)
    connected, _ = await communicator.connect()
    assert connected
    assert (await communicator.receive_json_from(timeout=5))["type"] == "snapshot"
    return communicator


async def _results(communicator, count: int) -> list[dict]:
    """The next `count` command results (live pushes in between skipped; bounded)."""
    found = []
    for _ in range(count + 50):
        message = await communicator.receive_json_from(timeout=5)
        if message.get("type") == "command.result":
            found.append(message)
            if len(found) == count:
                return found
    raise AssertionError(f"only {len(found)} of {count} results")


BAD_FRAMES = [
    ({"text_data": "{not json"}, "frame: not valid JSON"),
    ({"bytes_data": b"\x89PNG"}, "frame: binary frames are not accepted"),
    ({"text_data": "[" * 5000 + "]" * 5000}, "frame: not valid JSON"),
    ({"text_data": json.dumps({"command": "stop", "robots": [[[[[[[[[[1]]]]]]]]]]})}, "frame: nested deeper"),
    ({"text_data": json.dumps({"command": "stop", "robots": [10**30]})}, "robots: give"),
    (
        {"text_data": json.dumps({"command": "teleop", "robot": [1, 2], "linear": 0.1})},
        "robot: give one robot id",
    ),
    (
        {"text_data": json.dumps({"command": "teleop", "robot": 10**30, "linear": 0.1})},
        "robot: give one robot id",
    ),
    ({"text_data": json.dumps({"command": "dance"})}, "command: unknown"),
    ({"text_data": json.dumps({"type": "robot.status"})}, "command: unknown"),
    ({"text_data": "null"}, "frame: a JSON object is expected"),
]


@pytest.mark.parametrize(("frame", "says"), BAD_FRAMES, ids=lambda value: str(value)[:30])
@pytest.mark.django_db(transaction=True)
@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_bad_message_is_answered_in_words_and_the_socket_stays_open(
    operator, world, recorded_control, frame, says
):
    communicator = await _socket(operator)
    await communicator.send_to(**frame)
    (reply,) = await _results(communicator, 1)
    assert reply["ok"] is False and says in reply["detail"], reply
    assert "Traceback" not in reply["detail"]
    # the socket still serves: a stop after it is done
    await communicator.send_json_to({"command": "stop", "robots": [world["robot"].pk], "ref": "after"})
    (after,) = await _results(communicator, 1)
    assert after["ref"] == "after" and after["ok"] is True
    assert ("stop", operator.username) in recorded_control
    await communicator.disconnect()


@pytest.mark.django_db(transaction=True)
@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_stuck_teleop_key_is_limited_and_a_stop_still_gets_through(
    operator, world, recorded_control, monkeypatch
):
    """100 presses at once (a clock that does not move): 20 let through, one warning, then the stop is done. Of
    the 20, those not out yet when the STOP is read are not sent after it (execution.held_teleop)."""
    monkeypatch.setattr(socket_input, "RateLimiter", functools.partial(RateLimiter, clock=lambda: 50.0))
    communicator = await _socket(operator)
    robot = world["robot"].pk
    for i in range(100):
        await communicator.send_json_to({"command": "teleop", "robot": robot, "linear": 0.1, "ref": f"t{i}"})
    await communicator.send_json_to({"command": "stop", "robots": [robot], "ref": "stop"})
    replies = await _results(communicator, 22)  # 20 presses, 1 warning, 1 stop
    warnings = [r for r in replies if r["detail"].startswith("rate:")]
    assert len(warnings) == 1 and "teleop" in warnings[0]["detail"]
    assert [r["ref"] for r in replies if r["ref"] == "stop" and r["ok"]] == ["stop"]
    published = [call for call in recorded_control if call[0] == "teleop"]
    presses = [r for r in replies if r["ref"].startswith("t") and not r["detail"].startswith("rate:")]
    cut = [r for r in presses if not r["ok"] and "stopped after this command was sent" in r["detail"]]
    assert len(presses) == 20 and len(published) == sum(r["ok"] for r in presses)
    assert len(published) + len(cut) == 20  # each press let through was sent, or cut by the STOP, and said so
    await communicator.disconnect()


@pytest.mark.django_db(transaction=True)
@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_database_error_is_said_in_general_words(operator, world, recorded_control, monkeypatch):

    def locked(robots, user):
        raise OperationalError("database is locked")

    monkeypatch.setattr(execution.control, "stop", staticmethod(locked))
    communicator = await _socket(operator)
    await communicator.send_json_to({"command": "stop", "robots": [world["robot"].pk]})
    (reply,) = await _results(communicator, 1)
    assert reply["ok"] is False
    assert "database is busy" in reply["detail"] and "locked" not in reply["detail"]
    await communicator.disconnect()


@pytest.mark.django_db(transaction=True)
@pytest.mark.asyncio
@pytest.mark.timeout(60)
async def test_a_teleop_check_that_meets_a_database_error_is_said_in_general_words(
    operator, world, recorded_control, monkeypatch
):

    def locked(robot_ids, user):
        raise OperationalError("database is locked")

    monkeypatch.setattr(execution.control, "teleop_grants", staticmethod(locked))
    communicator = await _socket(operator)
    await communicator.send_json_to({"command": "teleop", "robot": world["robot"].pk, "linear": 0.1})
    (reply,) = await _results(communicator, 1)
    assert reply["ok"] is False
    assert "database is busy" in reply["detail"] and "locked" not in reply["detail"]
    await communicator.disconnect()
