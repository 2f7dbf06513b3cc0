"""A binding points only at a topic or action of a type its action accepts: API, admin forms, registration."""

import pytest
from django.core.exceptions import ValidationError
from django.urls import reverse

from robots.discovery import Graph, TopicInfo
from robots.identify import accepts, identify
from robots.models import Binding, Robot
from robots.registration import register_endpoints

pytestmark = [pytest.mark.timeout(60), pytest.mark.django_db]


@pytest.fixture
def fakebot(endpoint) -> Robot:
    """The fake endpoint's robot, registered (move -> /cmd_vel, odometry -> /odom)."""
    register_endpoints([endpoint().url])
    return Robot.objects.get(name="fakebot")


def test_the_api_refuses_a_move_binding_to_an_odometry_topic_and_keeps_the_old_one(
    fakebot, client_for, fleet_admin
):
    reply = client_for(fleet_admin).put(
        "/api/robots/fakebot/bindings/move", {"target": "/odom"}, content_type="application/json"
    )
    assert reply.status_code == 422
    assert reply.json()["detail"] == (
        "target: /odom is a nav_msgs/Odometry topic; move takes a geometry_msgs/Twist or "
        "geometry_msgs/TwistStamped topic"
    )
    assert fakebot.bindings.get(action="move").target == "/cmd_vel"


def test_the_api_accepts_a_topic_of_the_right_type(fakebot, client_for, fleet_admin):
    reply = client_for(fleet_admin).put(
        "/api/robots/fakebot/bindings/odometry", {"target": "/odom"}, content_type="application/json"
    )
    assert reply.status_code == 200 and reply.json()["how"] == "user"


def test_the_admins_form_refuses_a_target_of_the_wrong_type(fakebot):
    binding = fakebot.bindings.get(action="odometry")
    binding.target = "/cmd_vel"
    with pytest.raises(ValidationError) as info:
        binding.full_clean()
    assert "odometry takes a nav_msgs/Odometry topic" in info.value.message_dict["target"][0]
    binding.target = "/nope"
    with pytest.raises(ValidationError, match="is not a topic or action of fakebot"):
        binding.full_clean()


def test_a_wrong_typed_choice_stored_earlier_is_dropped_at_the_next_registration(fakebot):
    Binding.objects.filter(robot=fakebot, action="move").update(target="/odom", how=Binding.How.USER)
    (result,) = register_endpoints([fakebot.endpoint])
    move = fakebot.bindings.get(action="move")
    assert (move.target, move.message_type) == ("/cmd_vel", "geometry_msgs/Twist")
    assert result.changes["fakebot"]["user_choices_dropped"] == ["move: /odom"]


def test_navigate_binds_only_an_action_server_whose_goals_we_can_send():
    graph = Graph(url="ws://test:9090", actions={"/navigate_custom": "my_nav/GoSomewhere"})
    graph.topics["/cmd_vel"] = TopicInfo("/cmd_vel", "geometry_msgs/Twist", [], ["/base"])
    assert identify(graph)["navigate"].target == ""
    graph.actions["/navigate_to_pose"] = "nav2_msgs/action/NavigateToPose"
    assert identify(graph)["navigate"].target == "/navigate_to_pose"


@pytest.mark.parametrize(
    ("action", "kind", "type_", "ok"),
    [
        ("move", "topic", "geometry_msgs/msg/TwistStamped", True),
        ("move", "topic", "nav_msgs/Odometry", False),
        ("move", "action", "move_base_msgs/MoveBaseAction", False),
        ("odometry", "topic", "nav_msgs/msg/Odometry", True),
        ("navigate", "action", "move_base_msgs/MoveBaseAction", True),
        ("navigate", "topic", "geometry_msgs/PoseStamped", True),
        ("navigate", "service", "std_srvs/Empty", False),
        ("battery", "topic", "sensor_msgs/BatteryState", True),
        ("teleport", "topic", "geometry_msgs/Twist", False),
    ],
)
def test_what_each_action_accepts(action, kind, type_, ok):
    assert accepts(action, kind, type_) is ok


def test_the_registration_page_refuses_a_stale_candidate_of_the_wrong_type_with_a_message(
    fakebot, client_for, fleet_admin
):
    move = fakebot.bindings.get(action="move")
    move.candidates = [{"target": "/odom", "type": "nav_msgs/Odometry"}]  # stored before types were checked
    move.save()
    page = client_for(fleet_admin).post(
        reverse("choose-binding", args=[move.pk]), {"target": "/odom"}, follow=True
    )
    assert page.status_code == 200
    assert "move takes a geometry_msgs/Twist or geometry_msgs/TwistStamped topic" in page.content.decode()
    assert fakebot.bindings.get(action="move").target == "/cmd_vel"


def test_an_endpoint_typed_in_the_admin_is_checked_and_stored_by_address(settings):
    robot = Robot(name="typed", endpoint="ws://localhost:9090/")
    robot.clean()
    assert robot.endpoint == "ws://127.0.0.1:9090"
    robot.endpoint = "ws://127.0.0.1:99999"
    with pytest.raises(ValidationError, match="the port must be 1-65535"):
        robot.clean()
    settings.FLEET_ROBOT_ALLOWED_NETWORKS = ["10.0.0.0/8"]
    robot.endpoint = "ws://127.0.0.1:9090"
    with pytest.raises(ValidationError, match="outside the allowed robot networks"):
        robot.clean()
