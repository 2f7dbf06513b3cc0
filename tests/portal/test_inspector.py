"""The robot page's diagnostics and topic inspector below the browser: which statuses of a shared /diagnostics are a
robot's, what a status becomes on the page (levels, cut text), what the inspector shows of a message and its
rate, and that it looks only at the robot's own registered topics (over the page's socket, as a viewer)."""

import pytest

import live
from portal import inspector
from robots.models import Robot
from robots.sensors import DiagnosticsOwner


def test_a_robot_alone_on_its_endpoint_owns_every_status_robots_sharing_one_their_own(db):
    alone = Robot.objects.create(name="husky", model="husky", endpoint="ws://127.0.0.1:9092")
    first = Robot.objects.create(
        name="robot1", model="m", endpoint="ws://127.0.0.1:9090", namespace="/robot1"
    )
    Robot.objects.create(name="robot2", model="m", endpoint="ws://127.0.0.1:9090", namespace="/robot2")
    assert DiagnosticsOwner.of(alone).owns({"name": "twist_mux: inputs", "hardware_id": ""})
    owner = DiagnosticsOwner.of(first)
    assert owner.owns({"name": "robot1/battery", "hardware_id": ""})
    assert owner.owns({"name": "/robot1/turtlebot3_diagnostics: Battery", "hardware_id": ""})
    assert owner.owns({"name": "battery", "hardware_id": "robot1"})
    assert not owner.owns({"name": "robot2/battery", "hardware_id": "robot2"})
    assert not owner.owns({"name": "robot10/battery", "hardware_id": ""})  # a word, not a prefix


def test_a_status_on_the_page_has_a_known_level_and_cut_text():
    statuses = [
        {
            "name": "battery",
            "level": 1,
            "message": "low",
            "hardware_id": "h",
            "values": [{"key": "v", "value": 3}],
        },
        {"name": "odd", "level": 7, "message": "x" * 1000},
        {"name": "ros2 byte", "level": "\x02"},
        "not a status",
    ]
    out = live.diagnostics(3, "/diagnostics", statuses)["statuses"]
    assert [(s["name"], s["level_name"]) for s in out] == [
        ("battery", "WARN"),
        ("odd", "STALE"),
        ("ros2 byte", "ERROR"),
    ]
    assert out[0]["values"] == [["v", "3"]]
    assert len(out[1]["message"]) == live.TEXT_MAX


def test_the_inspector_shortens_long_arrays_and_strings_and_counts_a_rate():
    text = inspector.as_text({"ranges": list(range(720)), "data": "A" * 5000, "header": {"frame_id": "<b>"}})
    assert "… 708 more" in text and "(5000 characters)" in text and '"<b>"' in text
    rate = inspector.Rate()
    assert rate.words() == {"rate_hz": None, "capped": False, "count": 0}
    for i in range(11):
        rate.add(100.0 + i * 0.5)  # 2 Hz
    assert rate.words() == {"rate_hz": 2.0, "capped": False, "count": 11}
    fast = inspector.Rate()
    for i in range(40):
        fast.add(i * 0.1)  # 10 Hz: the throttle's cap, so at least that
    assert fast.words()["capped"] is True


@pytest.mark.django_db(transaction=True)
@pytest.mark.asyncio
@pytest.mark.timeout(30)
async def test_a_viewer_may_inspect_only_the_robots_own_topics(viewer, fleet):
    from asgiref.sync import sync_to_async

    from tests.portal.test_websockets import _connect

    husky = fleet["husky"]
    await sync_to_async(husky.topics.create)(name="/husky/odom", type="nav_msgs/Odometry")
    communicator = await _connect(f"/ws/robots/{husky.pk}/", viewer)
    assert (await communicator.receive_json_from(timeout=10))["type"] == "snapshot"

    answers = []
    for topic in ("/cmd_vel", "/odom", "x" * 300, 12):  # the turtlebot's topics, not husky's; nonsense
        await communicator.send_json_to({"command": "inspect", "topic": topic, "ref": str(topic)[:20]})
        answers.append(await _result(communicator))
    assert [a["ok"] for a in answers] == [False] * 4
    assert "not a topic of this robot" in answers[0]["detail"]
    await communicator.send_json_to({"command": "inspect", "topic": None})
    assert (await _result(communicator))["detail"] == "inspector off"
    await communicator.disconnect()


async def _result(communicator) -> dict:
    while True:
        message = await communicator.receive_json_from(timeout=10)
        if message.get("type") == "command.result":
            return message
