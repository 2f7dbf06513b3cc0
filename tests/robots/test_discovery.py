"""Discovery of one endpoint: graph, robots per namespace, infrastructure left out, ROS 1 vs 2."""

import asyncio

import pytest

from robots.discovery import READ_RETRIES, discover, is_infra, rosapi
from robots.rosbridge import RosbridgeTimeout
from tests.robots.fakes import big_graph, robot_graph

pytestmark = [pytest.mark.timeout(30)]


def run(coro):
    return asyncio.run(coro)


def three_robots(graph):
    for ns in ("/alpha", "/beta", "/gamma"):
        robot_graph(graph, ns)
    graph.add_publisher("/map_server", "/map", "nav_msgs/OccupancyGrid")


def test_single_robot_is_named_after_its_urdf_and_infrastructure_is_left_out(endpoint):
    ep = endpoint()
    (robot,) = run(discover(ep.url))
    assert (robot.name, robot.namespace, robot.ros_version) == ("fakebot", "", 1)
    assert set(robot.topics) == {"/cmd_vel", "/odom", "/scan"}
    assert robot.topics["/cmd_vel"].subscribers == ["/base_driver"]
    assert robot.topics["/odom"].publishers == ["/base_driver"]
    assert not any(is_infra(n, "service") for n in robot.services)
    assert not any(
        n.startswith(("/rosapi", "/rosbridge")) for n in [*robot.nodes, *robot.services, *robot.params]
    )
    assert robot.urdf.wheel_count == 2


def test_namespaced_endpoint_gives_one_robot_per_namespace_sharing_root_topics(endpoint):
    ep = endpoint(build=three_robots)
    robots = run(discover(ep.url))
    assert [r.name for r in robots] == ["alpha", "beta", "gamma"]
    beta = robots[1]
    assert set(beta.topics) == {"/beta/cmd_vel", "/beta/odom", "/beta/scan", "/map"}
    assert set(beta.nodes) == {"/beta/base_driver", "/beta/laser"}


def test_ros2_endpoint_is_detected_and_its_robot_description_param_read(endpoint):
    ep = endpoint(ros_version=2)
    (robot,) = run(discover(ep.url))
    assert robot.ros_version == 2
    assert robot.topics["/cmd_vel"].type == "geometry_msgs/msg/Twist"
    assert robot.urdf is not None and robot.urdf.name == "fakebot"
    assert not any(s.endswith("/get_parameters") for s in robot.services)


def test_broken_urdf_is_reported_not_fatal(endpoint):
    def broken(graph):
        robot_graph(graph)
        graph.params["/robot_description"] = "<robot name='x'><link>"

    (robot,) = run(discover(endpoint(build=broken).url))
    assert robot.urdf is None
    assert "not XML" in robot.urdf_error
    assert robot.name == ""  # no URDF name: registration names it after its model, never host:port
    assert "/cmd_vel" in robot.topics


def test_endpoint_with_1200_topics(endpoint):
    ep = endpoint(build=big_graph)
    (robot,) = run(discover(ep.url))
    assert len(robot.topics) == 1200
    assert robot.topics["/sensors/group_3/reading_3"].publishers == ["/sensor_node_3"]


def test_demo_world_endpoints(paper_world):
    async def all_endpoints():
        return await asyncio.gather(*(discover(u) for u in paper_world.urls.values()))

    found = dict(zip(paper_world.urls, run(all_endpoints()), strict=True))
    assert [g.name for g in found["robots"]] == ["robot1", "robot2", "robot3", "robot4"]
    assert [g.name for g in found["tiago"]] == ["tiago"]
    assert found["tb3_nav2"][0].ros_version == 2
    assert found["tb3_nav2"][0].actions == {
        "/navigate_to_pose": "nav2_msgs/action/NavigateToPose",
        "/navigate_through_poses": "nav2_msgs/action/NavigateThroughPoses",
        "/dock": "irobot_create_msgs/action/Dock",
    }
    assert found["robots"][0].actions == {"/robot1/move_base": "move_base_msgs/MoveBaseAction"}
    assert found["husky"][0].start_pose == pytest.approx([1.5, -1.3, 1.5708], abs=1e-3)


class _LateOnce:
    """A client whose endpoint answers each call only when asked again (the first answer came too late)."""

    url = "ws://busy"

    def __init__(self, silent_times: int) -> None:
        self.silent_times, self.asked = silent_times, []

    async def call_service(self, service, args=None):
        self.asked.append(service)
        if len(self.asked) <= self.silent_times:
            raise RosbridgeTimeout(f"{self.url}: no answer to {service} within 3 s")
        return {"value": '"tb3"'}


def test_a_rosapi_read_answered_late_is_asked_once_more_before_the_endpoint_fails():
    late = _LateOnce(silent_times=READ_RETRIES)
    assert run(rosapi(late, "/rosapi/get_param", {"name": "/robot_name"})) == {"value": '"tb3"'}
    assert late.asked == ["/rosapi/get_param"] * (READ_RETRIES + 1)

    silent = _LateOnce(silent_times=READ_RETRIES + 1)
    with pytest.raises(RosbridgeTimeout, match="no answer to /rosapi/get_param"):
        run(rosapi(silent, "/rosapi/get_param", {"name": "/robot_name"}))
    assert len(silent.asked) == READ_RETRIES + 1
