"""Bad input never crashes the simulator nor slows other clients: it is dropped or the client is cut off."""

import json
import logging
import socket
import time

import pytest
from websockets.exceptions import ConnectionClosed

import simworker.connection

pytestmark = pytest.mark.timeout(60)
TWIST = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


def server_of(sim, key):
    return sim.fleet.servers[key]


def assert_alive(client):
    """The endpoint still answers, and the client got no reply to what it sent before."""
    reply = client.call("/rosapi/get_time")
    assert reply["result"] is True and set(reply["values"]["time"]) == {"secs", "nsecs"}


def test_malformed_json_and_non_objects_are_dropped_silently(world, bridge):
    client = bridge(world.urls["turtlebot"])
    for frame in ("{not json", "[1, 2]", '"op"', "", b"\xff\xfe"):
        client.ws.send(frame)
    assert_alive(client)


@pytest.mark.parametrize("op", ["status", "set_level", "png", "fragment", "auth", 5, None])
def test_unknown_or_unsupported_ops_get_no_reply(world, bridge, op):
    client = bridge(world.urls["turtlebot"])
    client.send(op, level="info", id="x", data="x")
    assert_alive(client)


@pytest.mark.parametrize(
    "message",
    [
        {"op": "subscribe", "topic": 5},
        {"op": "subscribe", "topic": "/odom", "throttle_rate": "fast"},
        {"op": "publish", "topic": "/cmd_vel", "msg": "forward"},
        {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": "fast"}}},
        {"op": "publish", "topic": "/cmd_vel", "msg": {"linear": [1, 2]}},
        {"op": "publish", "topic": "/nobody/knows", "msg": {}},
        {"op": "advertise", "topic": "/cmd_vel", "type": "std_msgs/String"},
        {"op": "advertise", "topic": "/x"},
        {"op": "call_service", "service": ["/rosapi/topics"]},
        {"op": "call_service", "service": "/rosapi/topics", "args": 7},
        {"op": "unsubscribe"},
    ],
)
def test_wrong_field_types_are_dropped_and_do_not_move_the_robot(world, bridge, message):
    client = bridge(world.urls["turtlebot"])
    before = world.pose("turtlebot")
    client.ws.send(json.dumps(message))
    assert_alive(client)
    time.sleep(0.1)
    assert world.pose("turtlebot") == pytest.approx(before, abs=1e-6)
    assert client.call("/rosapi/topic_type", {"topic": "/cmd_vel"})["values"]["type"] == "geometry_msgs/Twist"


def test_failed_service_calls_answer_result_false_with_the_error(world, bridge):
    client = bridge(world.urls["turtlebot"])
    missing = client.call("/no/such/service")
    assert missing["result"] is False and missing["values"] == "Service /no/such/service does not exist"
    bad = client.call("/rosapi/set_param", {"name": "/x", "value": "not json"})
    assert bad["result"] is False and "not JSON" in bad["values"]


def test_a_50_mb_frame_closes_only_that_connection(world, bridge):
    big, other = bridge(world.urls["turtlebot"]), bridge(world.urls["turtlebot"])
    with pytest.raises(ConnectionClosed) as closed:
        big.ws.send(json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"pad": "x" * 50_000_000}}))
        big.recv(timeout=10)
    assert closed.value.rcvd is None or closed.value.rcvd.code == 1009  # message too big
    assert_alive(other)


def test_a_publish_flood_is_throttled_and_others_are_still_served(world, bridge):
    flooder, other = bridge(world.urls["turtlebot"]), bridge(world.urls["turtlebot"])
    steps_before = world.call(lambda: world.fleet.physics.steps)
    frame = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST})
    for _ in range(20_000):
        flooder.ws.send(frame)
    assert_alive(other)
    assert_alive(flooder)  # the flooder's own later messages still get through
    assert world.call(lambda: world.fleet.physics.steps) > steps_before
    dropped = world.call(lambda: sum(c.dropped for c in server_of(world, "turtlebot").clients))
    assert dropped > 0


def test_a_client_commanding_a_whole_shard_is_not_taken_for_a_flood():
    """The portal's one link to a 500-robot endpoint: a stop-all's zeros and every held button (5 Hz) in one
    second are not dropped; a client of a one-robot endpoint sending as many is (rosbridge drops neither: the
    bound is the simulator's own, against a client flooding a topic)."""
    shard = simworker.connection.Client(ws=None, topics=500)
    one_robot = simworker.connection.Client(ws=None, topics=3)
    burst = 500 + 5 * 500
    assert sum(shard.allow() for _ in range(burst)) == burst
    assert sum(one_robot.allow() for _ in range(burst)) < burst


def raw_subscriber(url: str, subscribe: list[dict]) -> socket.socket:
    """Open a WebSocket by hand, send frames, and never read again."""
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)))
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.sendall(
        f"GET / HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    for msg in subscribe:
        payload = json.dumps(msg).encode()
        header = (
            bytes([0x81, 0x80 | 126]) + len(payload).to_bytes(2, "big") + b"\0\0\0\0"
        )  # masked, zero mask
        sock.sendall(header + payload)
    return sock


def test_a_client_that_never_reads_is_bounded_then_cut_off(world, bridge, monkeypatch):
    monkeypatch.setattr(simworker.connection, "STALL_SECONDS", 1.0)
    server = server_of(world, "robots")
    calls = [{"op": "call_service", "service": "/robot1/static_map", "id": str(i)} for i in range(100)]
    silent = raw_subscriber(world.urls["robots"], [{"op": "subscribe", "topic": "/robot1/map"}, *calls])
    reader = bridge(world.urls["robots"])
    reader.send("subscribe", topic="/robot2/odom", id="o")
    received = 0
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        if reader.recv(timeout=5).get("topic") == "/robot2/odom":
            received += 1
        queues = world.call(lambda: [len(c.queue) for c in server.clients])
        assert max(queues) <= simworker.connection.SEND_QUEUE
        if received >= 40 and len(queues) == 1:
            break
    assert received >= 40  # the reader kept getting odometry all along
    assert world.call(lambda: len(server.clients)) == 1  # the silent client was disconnected
    silent.close()


def test_a_full_send_queue_drops_the_oldest_and_says_so(caplog):
    caplog.set_level(logging.WARNING, logger="simworker.server")
    client = simworker.connection.Client(ws=None)
    limit = simworker.connection.SEND_QUEUE
    for i in range(limit + 5):
        client.send(f"message {i}")
    assert len(client.queue) == limit and client.queue[0][0] == "message 5"  # the oldest five went
    assert client.overflowed == client.dropped == 5
    said = [r.getMessage() for r in caplog.records if "send queue full" in r.getMessage()]
    assert len(said) == 1 and said[0].endswith("the oldest dropped, 1 so far")  # one line, not one per drop
