"""The camera binding role: which topic of a robot's graph a photo is taken from, and what its page shows."""

import pytest

from fleetcore.catalog import MODELS
from robots.discovery import Graph, TopicInfo
from robots.identify import identify
from robots.models import Robot
from robots.sensors import feeds
from simworker.interfaces import BUILDERS, build_interface
from tests.robots.test_identify import make_graph

IMAGE, COMPRESSED = "sensor_msgs/Image", "sensor_msgs/CompressedImage"


def simulated_graph(model: str, ros_version: int) -> Graph:
    """The graph the simulator shows for one robot of this model (simworker.interfaces), without a server."""
    iface = build_interface(MODELS[model], "", ros_version, "", model)
    graph = Graph(url="ws://test:9090", ros_version=ros_version)
    for node, entry in iface.nodes.items():
        graph.nodes[node] = {"publishing": [*entry["pubs"]], "subscribing": [*entry["subs"]], "services": []}
        for kind, side in (("pubs", "publishers"), ("subs", "subscribers")):
            for topic, type_ in entry[kind].items():
                info = graph.topics.setdefault(topic, TopicInfo(topic, type_, [], []))
                getattr(info, side).append(node)
    return graph


@pytest.mark.parametrize(("model", "ros_version"), sorted(BUILDERS))
def test_the_simulators_tiago_has_its_xtion_bound_as_camera_and_no_other_robot_a_camera(model, ros_version):
    camera = identify(simulated_graph(model, ros_version))["camera"]
    if model == "tiago":
        assert (camera.target, camera.message_type) == ("/xtion/rgb/image_raw/compressed", COMPRESSED)
        assert not camera.needs_user
    else:
        assert (camera.target, camera.needs_user) == ("", False)  # optional: absent, not a question


def test_a_compressed_colour_frame_beats_the_raw_one_and_a_depth_image_is_never_the_camera():
    """A real TIAGo's head camera: raw and compressed colour, depth in both forms."""
    graph = make_graph(
        [
            ("/xtion/rgb/image_raw", IMAGE, ["/xtion"], []),
            ("/xtion/rgb/image_raw/compressed", COMPRESSED, ["/xtion"], []),
            ("/xtion/depth_registered/image_raw", IMAGE, ["/xtion"], []),
            ("/xtion/depth_registered/image_raw/compressedDepth", COMPRESSED, ["/xtion"], []),
        ]
    )
    result = identify(graph)["camera"]
    assert result.target == "/xtion/rgb/image_raw/compressed"
    assert [c["target"] for c in result.candidates][-2:] == [
        "/xtion/depth_registered/image_raw",
        "/xtion/depth_registered/image_raw/compressedDepth",
    ]


def test_a_raw_camera_alone_is_bound_as_the_camera():
    graph = make_graph([("/camera/image_raw", IMAGE, ["/usb_cam"], [])])
    assert (identify(graph)["camera"].target, identify(graph)["camera"].how) == ("/camera/image_raw", "exact")


@pytest.mark.django_db
def test_the_page_shows_the_bound_camera_and_a_compressed_topic_when_the_binding_is_raw():
    robot = Robot.objects.create(name="tiago", model="tiago", endpoint="ws://127.0.0.1:9093")
    robot.topics.create(name="/a/image/compressed", type=COMPRESSED)
    robot.topics.create(name="/xtion/rgb/image_raw/compressed", type=COMPRESSED)
    binding = robot.bindings.create(action="camera", target="/xtion/rgb/image_raw/compressed")
    binding.message_type = COMPRESSED
    binding.save()
    # the binding, not the first compressed topic of the graph
    assert feeds(robot)["camera"].topic == "/xtion/rgb/image_raw/compressed"
    binding.target, binding.message_type = "/xtion/rgb/image_raw", IMAGE
    binding.save()
    assert feeds(robot)["camera"].topic == "/a/image/compressed"  # raw frames: a browser cannot show them
