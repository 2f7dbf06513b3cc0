"""Our rosbridge frames are the ones roslibpy 2.1 builds (ids, keys, defaults), checked against roslibpy itself."""

import roslibpy

from robots.rosbridge import codec


class RecordingRos:
    """Stands in for roslibpy.Ros: counts ids like it and records what would be sent (no reactor, no socket)."""

    def __init__(self):
        self._id = 0
        self.sent = []

    @property
    def id_counter(self):
        self._id += 1
        return self._id

    def send_on_ready(self, message):
        self.sent.append(dict(message))

    def call_async_service(self, message, callback, errback):
        self.sent.append(dict(message))

    def call_async_action(self, message, resultback, feedback, errback):
        self.sent.append(dict(message))

    def on(self, *args):
        pass

    def off(self, *args):
        pass

    def call_later(self, *args):
        pass


def test_call_service_matches_roslibpy():
    ros = RecordingRos()
    roslibpy.Service(ros, "/rosapi/topics", "rosapi/Topics").call(roslibpy.ServiceRequest({"a": 1}), print)
    ours = codec.call_service(codec.Ids(), "/rosapi/topics", {"a": 1})
    assert ours == ros.sent[0]
    assert ours["id"] == "call_service:/rosapi/topics:1"


def test_subscribe_and_unsubscribe_match_roslibpy():
    ros = RecordingRos()
    topic = roslibpy.Topic(ros, "/odom", "nav_msgs/Odometry", throttle_rate=50, queue_length=1)
    topic.subscribe(print)
    topic.unsubscribe()
    ours = codec.subscribe(codec.Ids(), "/odom", "nav_msgs/Odometry", throttle_rate=50, queue_length=1)
    assert ours == ros.sent[0]
    assert codec.unsubscribe(ours["id"], "/odom") == ros.sent[1]


def test_advertise_publish_and_unadvertise_match_roslibpy():
    ros = RecordingRos()
    topic = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist")
    msg = {"linear": {"x": 0.1, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0.5}}
    topic.publish(roslibpy.Message(msg))
    topic.unadvertise()
    ids = codec.Ids()
    advertise = codec.advertise(ids, "/cmd_vel", "geometry_msgs/Twist")
    assert [
        advertise,
        codec.publish(ids, "/cmd_vel", msg),
        codec.unadvertise(advertise["id"], "/cmd_vel"),
    ] == ros.sent


def test_action_goal_and_cancel_match_roslibpy():
    ros = RecordingRos()
    action = roslibpy.ActionClient(ros, "/navigate_to_pose", "nav2_msgs/action/NavigateToPose")
    goal_id = action.send_goal(roslibpy.core.Goal({"pose": {}}), print, print, print)
    action.cancel_goal(goal_id)
    ours = codec.send_action_goal(
        codec.Ids(), "/navigate_to_pose", "nav2_msgs/action/NavigateToPose", {"pose": {}}
    )
    assert ours == ros.sent[0]
    assert codec.cancel_action_goal(ours["id"], "/navigate_to_pose") == ros.sent[1]


def test_decode_rejects_what_is_not_rosbridge():
    import pytest

    from robots.rosbridge import NotRosbridgeError

    for raw in ("<html>", "[1, 2]", '{"no_op": 1}', b"\xff\xfe"):
        with pytest.raises(NotRosbridgeError):
            codec.decode(raw)
    assert codec.decode('{"op": "publish", "topic": "\\/odom"}')["topic"] == "/odom"
    for raw in ('{"op": "publish", "msg": ' + "[" * 100_000 + "]" * 100_000 + "}", '{"op": "x"} trailing'):
        with pytest.raises(NotRosbridgeError):
            codec.decode(raw)


def test_decode_reads_what_rosbridge_writes_for_bad_odometry_and_exact_floats():
    """rosbridge's json.dumps writes NaN and Infinity bare: the pose gate must see them, not a refused frame."""
    import math

    msg = codec.decode(
        '{"op":"publish","msg":{"x":NaN,"y":-Infinity,"z":0.1,"w":1.0000000000000002,"n":12}}'
    )["msg"]
    assert math.isnan(msg["x"]) and msg["y"] == -math.inf
    assert (msg["z"], msg["w"], msg["n"]) == (0.1, 1.0000000000000002, 12) and isinstance(msg["n"], int)


def test_fragments_reassemble_with_a_float_total():
    frags = codec.Fragments(max_bytes=1_000_000)
    text = codec.encode({"op": "publish", "topic": "/map", "msg": {"data": list(range(20))}})
    parts = [text[i : i + 10] for i in range(0, len(text), 10)]
    total = (len(text) - 1) / 10 + 1  # rosbridge's true-division quirk
    out = [
        frags.add({"op": "fragment", "id": 7, "data": p, "num": i, "total": total})
        for i, p in enumerate(parts)
    ]
    assert out[:-1] == [None] * (len(parts) - 1)
    assert out[-1]["msg"]["data"] == list(range(20))
