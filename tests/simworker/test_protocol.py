"""rosbridge v2 behaviour of an endpoint: echo, throttle, unsubscribe, params, client services, fragments."""

import contextlib
import itertools
import json
import socket
import time

import pytest

pytestmark = pytest.mark.timeout(60)
TWIST = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.3}}


def test_a_published_twist_is_echoed_to_other_subscribers_without_id_or_type(world, bridge):
    pub, sub = bridge(world.urls["tiago"]), bridge(world.urls["tiago"])
    sub.send("subscribe", topic="/key_vel", type="geometry_msgs/Twist", id="s")
    sub.call("/rosapi/get_time")  # the subscription is in place once this answers
    pub.send("advertise", topic="/key_vel", type="geometry_msgs/Twist", id="a")
    pub.send("publish", topic="/key_vel", msg=TWIST, id="p")
    echoed = sub.wait_for(lambda m: m.get("topic") == "/key_vel", timeout=5)
    assert echoed == {"op": "publish", "topic": "/key_vel", "msg": TWIST}
    assert (
        "/rosbridge_websocket"
        in pub.call("/rosapi/publishers", {"topic": "/key_vel"})["values"]["publishers"]
    )
    assert "/twist_mux" in pub.call("/rosapi/subscribers", {"topic": "/key_vel"})["values"]["subscribers"]


def test_throttle_rate_limits_and_unsubscribe_stops_messages(world, bridge):
    client = bridge(world.urls["turtlebot"])
    client.send("subscribe", topic="/odom", id="slow", throttle_rate=500)
    start = time.monotonic()
    stamps = [client.wait_for(lambda m: m.get("topic") == "/odom") for _ in range(3)]
    assert time.monotonic() - start > 0.9  # three messages at most 2 per second
    assert len({json.dumps(m["msg"]["header"]) for m in stamps}) == 3
    client.send("unsubscribe", topic="/odom", id="slow")
    client.call("/rosapi/get_time")
    with pytest.raises(TimeoutError):
        client.wait_for(lambda m: m.get("topic") == "/odom", timeout=0.5)


@pytest.mark.parametrize(
    ("queue_length", "expected"),
    [(0, ["1"]), (2, ["1", "4", "5"])],
    ids=["a throttle alone drops", "a throttle with a queue keeps the newest"],
)
def test_a_burst_under_a_throttle_is_dropped_or_queued_as_rosbridge_does(
    world, bridge, queue_length, expected
):
    """rosbridge_library's subscription modifiers: under a throttle alone what comes within the interval is dropped;
    with a queue_length the newest wait (the older dropped) and one goes each interval."""
    pub, sub = bridge(world.urls["tiago"]), bridge(world.urls["tiago"])
    sub.send("subscribe", topic="/chatter", type="std_msgs/String", id="s", throttle_rate=300,
             queue_length=queue_length)  # fmt: skip
    sub.call("/rosapi/get_time")  # the subscription is in place once this answers
    pub.send("advertise", topic="/chatter", type="std_msgs/String", id="a")
    for n in range(1, 6):
        pub.send("publish", topic="/chatter", msg={"data": str(n)})
    got, times = [], []
    with contextlib.suppress(TimeoutError):
        while len(got) < 5:
            got.append(sub.wait_for(lambda m: m.get("topic") == "/chatter", timeout=1.0)["msg"]["data"])
            times.append(time.monotonic())
    assert got == expected
    assert all(b - a >= 0.25 for a, b in itertools.pairwise(times))  # one an interval (300 ms)


def test_odometry_for_a_throttled_subscriber_alone_is_built_only_when_it_is_sent(world, bridge):
    """As rosbridge serialises nothing for a throttled subscriber: 20 Hz odometry under a 500 ms throttle is
    written out about twice a second (the cost of a robot), while its seq counts every message of the 20 Hz."""
    server, built = world.fleet.servers["turtlebot"], []
    publish_text = server.publish_text
    server.publish_text = lambda topic, text: (
        topic == "/odom" and built.append(topic),
        publish_text(topic, text),
    )
    client = bridge(world.urls["turtlebot"])
    client.send("subscribe", topic="/odom", id="slow", throttle_rate=500)
    first = client.wait_for(lambda m: m.get("topic") == "/odom")
    built.clear()
    second = client.wait_for(lambda m: m.get("topic") == "/odom")
    third = client.wait_for(lambda m: m.get("topic") == "/odom")
    assert len(built) <= 3  # two sent, at most one more begun: not the ~20 of a second at 20 Hz
    seqs = [m["msg"]["header"]["seq"] for m in (first, second, third)]
    assert all(b - a >= 5 for a, b in itertools.pairwise(seqs))  # ~10 at 20 Hz under 500 ms


def test_odometry_held_for_a_queued_subscriber_is_written_only_when_it_goes(world, bridge, monkeypatch):
    """A throttle with a queue_length holds the newest message for its turn (rosbridge's QueueMessageHandler),
    which serialises the ROS message as it goes out: one replaced by a newer one is never written. 20 Hz
    odometry held for a 500 ms turn is written about twice a second, not twenty times."""
    import simworker.robot

    built, text_of = [], simworker.robot._odometry_text
    monkeypatch.setattr(simworker.robot, "_odometry_text", lambda *args: built.append(1) or text_of(*args))
    client = bridge(world.urls["turtlebot"])
    client.send("subscribe", topic="/odom", id="held", throttle_rate=500, queue_length=1)
    first = client.wait_for(lambda m: m.get("topic") == "/odom")
    built.clear()
    second = client.wait_for(lambda m: m.get("topic") == "/odom")
    third = client.wait_for(lambda m: m.get("topic") == "/odom")
    assert 2 <= len(built) <= 3  # the two sent, at most one more held: not the ~20 of a second at 20 Hz
    seqs = [m["msg"]["header"]["seq"] for m in (first, second, third)]
    assert all(b - a >= 5 for a, b in itertools.pairwise(seqs))  # the newest each turn: ~10 at 20 Hz


def test_ros1_params_get_set_has_and_namespaces(world, bridge):
    client = bridge(world.urls["robots"])
    tree = json.loads(client.call("/rosapi/get_param", {"name": "/robot1"})["values"]["value"])
    assert tree["robot_description"].startswith("<?xml") and tree["move_base"]["controller_frequency"] == 10.0
    assert client.call("/rosapi/set_param", {"name": "/demo/speed", "value": "0.5"})["result"] is True
    assert client.call("/rosapi/get_param", {"name": "/demo/speed"})["values"]["value"] == "0.5"
    assert client.call("/rosapi/has_param", {"name": "/demo/speed"})["values"]["exists"] is True
    missing = client.call("/rosapi/get_param", {"name": "/nope", "default": "3"})
    assert missing["values"]["value"] == "3"
    assert "/robot4/robot_description" in client.call("/rosapi/get_param_names")["values"]["names"]


def test_ros2_endpoint_speaks_ros2(world, bridge):
    client = bridge(world.urls["tb3_nav2"])
    assert client.call("/rosapi/get_time")["values"]["time"].keys() == {"sec", "nanosec"}
    assert client.call("/rosapi/get_ros_version")["values"] == {"version": 2, "distro": "humble"}
    names = client.call("/rosapi/get_param_names")["values"]["names"]
    assert "/robot_state_publisher:robot_description" in names
    assert "/turtlebot3_node/get_parameters" in client.call("/rosapi/services")["values"]["services"]
    assert client.call("/rosapi/topic_type", {"topic": "/odom"})["values"]["type"] == "nav_msgs/msg/Odometry"
    client.send("subscribe", topic="/robot_description", id="d")
    assert (
        "wheel_left_joint" in client.wait_for(lambda m: m.get("topic") == "/robot_description")["msg"]["data"]
    )
    client.send("subscribe", topic="/odom", id="o")
    odom = client.wait_for(lambda m: m.get("topic") == "/odom")["msg"]
    assert odom["header"]["stamp"].keys() == {"sec", "nanosec"} and "seq" not in odom["header"]


def test_client_count_is_latched_and_infrastructure_is_listed(world, bridge):
    client = bridge(world.urls["husky"])
    client.send("subscribe", topic="/client_count", id="c")
    assert client.wait_for(lambda m: m.get("topic") == "/client_count")["msg"]["data"] >= 1
    values = client.call("/rosapi/topics_for_type", {"type": "nav_msgs/Odometry"})["values"]
    assert {"/odometry/filtered", "/husky_velocity_controller/odom"} <= set(values["topics"])
    services = client.call("/rosapi/services")["values"]["services"]
    assert {"/move_base/make_plan", "/twist_mux/get_loggers", "/rosapi/get_param"} <= set(services)


def test_client_advertised_service_is_forwarded_and_answered(world, bridge):
    provider, caller = bridge(world.urls["spot"]), bridge(world.urls["spot"])
    provider.send("advertise_service", service="/my_service", type="std_srvs/Trigger")
    provider.call("/rosapi/get_time")
    caller.send("call_service", service="/my_service", args={}, id="c1")
    request = provider.wait_for(lambda m: m.get("op") == "call_service")
    assert request["service"] == "/my_service" and request["id"].startswith("service_request:/my_service:")
    provider.send(
        "service_response",
        service="/my_service",
        id=request["id"],
        result=True,
        values={"success": True, "message": "done"},
    )
    answer = caller.wait_for(lambda m: m.get("op") == "service_response")
    assert answer == {
        "op": "service_response",
        "service": "/my_service",
        "id": "c1",
        "values": {"success": True, "message": "done"},
        "result": True,
    }
    provider.send("unadvertise_service", service="/my_service")
    assert caller.call("/my_service")["result"] is False


def test_fragments_are_reassembled(world, bridge):
    client = bridge(world.urls["turtlebot"])
    text = json.dumps({"op": "call_service", "service": "/rosapi/get_time", "id": "frag"})
    parts = [text[i : i + 10] for i in range(0, len(text), 10)]
    for num, data in reversed(list(enumerate(parts))):
        client.send("fragment", id="f1", data=data, num=num, total=len(parts))
    assert client.wait_for(lambda m: m.get("id") == "frag")["result"] is True


def test_a_burst_of_messages_is_handled_without_a_turn_of_the_loop_each(world):
    """Messages already read are handled one after another, as rosbridge does; a turn of the loop for each made a
    stop's zeros wait behind a fleet's commands, a turn each, on a loaded endpoint (simworker.server.BURST_S)."""
    zero = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
    frames = b"".join(
        _masked(json.dumps({"op": "publish", "topic": "/robot1/cmd_vel", "msg": zero})) for _ in range(300)
    )
    graph = world.fleet.servers["robots"].graph
    turns, seen = [0], []

    def spin():  # one call a turn of the loop, until the burst is handled
        turns[0] += 1
        if len(seen) < 300:
            world.loop.call_soon(spin)

    def record(_msg):
        seen.append(turns[0])

    world.call(graph.on_topic, "/robot1/cmd_vel", record)
    host, port = world.urls["robots"].removeprefix("ws://").rsplit(":", 1)
    with socket.create_connection((host, int(port))) as sock:
        sock.sendall(
            f"GET / HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
        )
        sock.recv(4096)  # the handshake's answer: the connection is open
        world.call(spin)
        sock.sendall(frames)  # 300 publishes in one write
        deadline = time.monotonic() + 10
        while len(seen) < 300 and time.monotonic() < deadline:
            time.sleep(0.01)
    world.call(graph.topic_handlers["/robot1/cmd_vel"].remove, record)
    assert len(seen) == 300
    assert seen[-1] - seen[0] < 100  # a turn per message would be 299 or more


def _masked(text: str) -> bytes:
    """One client text frame (masked, zero mask) of a payload under 64 KB."""
    payload = text.encode()
    return bytes([0x81, 0x80 | 126]) + len(payload).to_bytes(2, "big") + b"\0\0\0\0" + payload
