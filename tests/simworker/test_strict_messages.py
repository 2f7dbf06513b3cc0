"""The simulator treats messages as rosbridge_suite's server does: completed with defaults, or dropped with the
real server's log line (rosbridge_library's message_conversion and protocol texts, ROS 1 and ROS 2 flavours)."""

import base64
import io
import json
import logging

import cbor2
import pytest
from PIL import Image

pytestmark = pytest.mark.timeout(60)
ENDPOINTS = {1: "turtlebot", 2: "tb3_nav2"}
DOUBLE = {1: "float64", 2: "double"}
DROPS = {
    # name: (topic, type, message, the log line's text after "[Client <uuid>] [id: p] ", by ROS version)
    "an int on a string": ("/strict_chatter", "std_msgs/String", {"data": 5},
                           "publish: std_msgs/String message requires a string for field data, but got a <class 'int'>"),
    "an extra field": ("/strict_chatter", "std_msgs/String", {"data": "hi", "loud": True},
                       "publish: Message type std_msgs/String does not have a field loud"),
    "a word for a number": ("/strict_twist", "geometry_msgs/Twist", {"linear": {"x": "fast"}},
                            "publish: geometry_msgs/Twist message requires a {double} for field linear.x, but got a"
                            " <class 'str'>"),
}  # fmt: skip


def _listen(world, bridge, ros, topic, type_):
    """A subscriber (in place) and a publisher (advertised) on topic at the endpoint of that ROS version."""
    url = world.urls[ENDPOINTS[ros]]
    pub, sub = bridge(url), bridge(url)
    pub.send("advertise", topic=topic, type=type_, id="a")
    sub.send("subscribe", topic=topic, type=type_, id="s")
    sub.call("/rosapi/get_time")  # the subscription is in place once this answers
    return pub, sub


@pytest.mark.parametrize("ros", ENDPOINTS)
@pytest.mark.parametrize("case", DROPS)
def test_a_message_that_does_not_fit_its_type_is_dropped_with_the_real_servers_line(
    world, bridge, caplog, ros, case
):
    topic, type_, msg, line = DROPS[case]
    pub, sub = _listen(world, bridge, ros, topic, type_)
    with caplog.at_level(logging.ERROR, logger="simworker.server"):
        pub.send("publish", topic=topic, msg=msg, id="p")
        pub.call("/rosapi/get_time")  # the publish was handled once this answers
    expected = line.format(double=DOUBLE[ros])
    assert any(r.getMessage().endswith(f"] [id: p] {expected}") for r in caplog.records), caplog.text
    with pytest.raises(TimeoutError):
        sub.wait_for(lambda m: m.get("topic") == topic, timeout=0.5)


@pytest.mark.parametrize("ros", ENDPOINTS)
def test_a_partial_twist_arrives_as_a_full_twist(world, bridge, ros):
    pub, sub = _listen(world, bridge, ros, "/strict_twist", "geometry_msgs/Twist")
    pub.send("publish", topic="/strict_twist", msg={"linear": {"x": 1}})
    got = sub.wait_for(lambda m: m.get("topic") == "/strict_twist", timeout=5)["msg"]
    assert got == {"linear": {"x": 1.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
    assert isinstance(got["linear"]["x"], float)


def test_subscribing_with_another_type_streams_nothing(world, bridge, caplog):
    pub, _sub = _listen(world, bridge, 2, "/strict_chatter", "std_msgs/String")
    wrong = bridge(world.urls["tb3_nav2"])
    with caplog.at_level(logging.ERROR, logger="simworker.server"):
        wrong.send("subscribe", topic="/strict_chatter", type="std_msgs/Int32", id="w")
        wrong.call("/rosapi/get_time")
    pub.send("publish", topic="/strict_chatter", msg={"data": "hello"})
    assert (
        "[id: w] subscribe: Tried to register topic /strict_chatter with type std_msgs/msg/Int32 but it is already"
        " established with type std_msgs/msg/String" in caplog.text
    )
    with pytest.raises(TimeoutError):
        wrong.wait_for(lambda m: m.get("topic") == "/strict_chatter", timeout=0.5)


def test_service_response_result_is_not_read_and_values_are_not_stringified(world, bridge):
    provider, caller = bridge(world.urls["turtlebot"]), bridge(world.urls["turtlebot"])
    provider.send("advertise_service", service="/strict_sum", type="rospy_tutorials/AddTwoInts")
    provider.call("/rosapi/get_time")
    caller.send("call_service", service="/strict_sum", args=[2, 40], id="c")  # positional args
    request = provider.wait_for(lambda m: m.get("op") == "call_service", timeout=5)
    assert request["args"] == {"a": 2, "b": 40}
    provider.send(
        "service_response", service="/strict_sum", id=request["id"], values={"sum": 42}, result=False
    )
    answer = caller.wait_for(lambda m: m.get("id") == "c", timeout=5)
    assert answer["values"] == {"sum": 42} and answer["result"] is True


def test_png_cbor_and_fragment_size_shape_what_goes_out(world, bridge):
    pub, plain = _listen(world, bridge, 2, "/strict_points", "std_msgs/Float64MultiArray")
    png, cbor, small = (bridge(world.urls["tb3_nav2"]) for _ in range(3))
    png.send("subscribe", topic="/strict_points", compression="png")
    cbor.send("subscribe", topic="/strict_points", compression="cbor")
    small.send("subscribe", topic="/strict_points", fragment_size=50)  # from now on for all it is sent
    pub.send("publish", topic="/strict_points", msg={"data": [1.5, 2.5]})
    sent = plain.wait_for(lambda m: m.get("topic") == "/strict_points")["msg"]
    for _ in range(3):  # the subscriptions are in place after a round trip of their own: publish again
        pub.call("/rosapi/get_time")
        pub.send("publish", topic="/strict_points", msg={"data": [1.5, 2.5]})
    image = png.wait_for(lambda m: m.get("op") == "png")
    pixels = Image.open(io.BytesIO(base64.b64decode(image["data"]))).convert("RGB").tobytes()
    assert json.loads(pixels.decode().rstrip("\n"))["msg"] == sent
    decoded = cbor2.loads(cbor.ws.recv(timeout=5))
    assert decoded["msg"]["data"] == cbor2.CBORTag(
        86, b"\x00\x00\x00\x00\x00\x00\xf8?\x00\x00\x00\x00\x00\x00\x04@"
    )
    parts = [small.wait_for(lambda m: m.get("op") == "fragment") for _ in range(3)]
    assert parts[0]["id"] == 0 and parts[0]["total"] > 2 and all(len(p["data"]) <= 50 for p in parts)
    assert "".join(p["data"] for p in parts).startswith('{"op":"publish","topic":"/strict_points"')


@pytest.mark.parametrize("ros", ENDPOINTS)
def test_rosapi_typedefs_positional_args_and_unknown_fields(world, bridge, ros):
    client = bridge(world.urls[ENDPOINTS[ros]])
    typedefs = client.call("/rosapi/message_details", {"type": "geometry_msgs/Twist"})["values"]["typedefs"]
    assert [t["type"] for t in typedefs] == ["geometry_msgs/Twist", "geometry_msgs/Vector3"]
    assert typedefs[1]["fieldnames"] == ["x", "y", "z"] and typedefs[1]["fieldtypes"] == [DOUBLE[ros]] * 3
    request = client.call("/rosapi/service_request_details", {"type": "std_srvs/SetBool"})["values"][
        "typedefs"
    ]
    assert request[0]["fieldnames"] == ["data"]
    srv = "/rosapi/topic_type"
    assert client.call(srv, ["/odom"])["values"]["type"].endswith("Odometry")  # positional args
    refused = client.call(srv, {"topic": "/odom", "colour": "red"})
    pkg = "rosapi/TopicTypeRequest" if ros == 1 else "rosapi_msgs/TopicType_Request"
    assert (
        refused["result"] is False and refused["values"] == f"Message type {pkg} does not have a field colour"
    )
