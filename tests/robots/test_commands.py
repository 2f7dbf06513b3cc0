"""The command surface: what every publisher to a robot (executor, stops, teleop, watchdog, reconnect) sends."""

import pytest

from robots.commands import NAV_MOVE_BASE, NAV_NAV2, NAV_SIMPLE, CommandSurface, NoMoveTopic, surfaces
from robots.models import Binding, Robot

pytestmark = pytest.mark.django_db


def robot_with(name: str, ros_version: int, **bound) -> Robot:
    robot = Robot.objects.create(name=name, endpoint=f"ws://127.0.0.1:1/{name}", ros_version=ros_version)
    for action, (target, message_type) in bound.items():
        Binding.objects.create(robot=robot, action=action, target=target, message_type=message_type)
    return robot


def test_a_ros1_robot_with_move_base_is_stopped_by_a_zero_and_a_cancel_of_every_goal():
    robot = robot_with(
        "r1",
        1,
        move=("/r1/cmd_vel", "geometry_msgs/Twist"),
        navigate=("/r1/move_base/goal", "move_base_msgs/MoveBaseActionGoal"),
    )
    surface = CommandSurface.of(robot)
    assert surface.nav_kind == NAV_MOVE_BASE
    (topic, zero, type_), (cancel, goal_id, cancel_type) = surface.zero(t=5.0)
    assert (topic, type_) == ("/r1/cmd_vel", "geometry_msgs/Twist")
    assert zero == {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
    assert (cancel, cancel_type) == ("/r1/move_base/cancel", "actionlib_msgs/GoalID")
    assert goal_id["id"] == ""  # every goal
    assert surface.move_base_goal(1.0, 2.0, 0.0, "g7", 5.0)[0] == "/r1/move_base/goal"


def test_a_ros2_robot_speaks_twist_stamped_and_takes_nav2_goals_and_docks():
    robot = robot_with(
        "r2",
        2,
        move=("/cmd_vel", "geometry_msgs/msg/TwistStamped"),
        navigate=("/navigate_to_pose/_action/send_goal", "nav2_msgs/action/NavigateToPose"),
        dock=("/dock/_action/send_goal", "irobot_create_msgs/action/Dock"),
    )
    surface = CommandSurface.of(robot)
    topic, message, type_ = surface.velocity(0.3, -0.1, t=1.5)
    assert (topic, type_) == ("/cmd_vel", "geometry_msgs/msg/TwistStamped")
    assert message["twist"]["linear"]["x"] == 0.3 and message["twist"]["angular"]["z"] == -0.1
    assert message["header"]["stamp"] == {"sec": 1, "nanosec": 500_000_000}
    assert surface.nav_kind == NAV_NAV2 and surface.nav_namespace == "/navigate_to_pose"
    assert len(surface.zero()) == 1  # nav2 goals are cancelled by their action client, not by a topic
    assert surface.can_dock and surface.dock_namespace == "/dock"


def test_a_pose_stamped_goal_topic_and_a_robot_without_a_move_topic():
    simple = robot_with("r3", 1, navigate=("/r3/goal", "geometry_msgs/PoseStamped"))
    surface = CommandSurface.of(simple)
    assert surface.nav_kind == NAV_SIMPLE
    assert surface.simple_goal(1.0, 0.0, 0.0, 0.0)[0] == "/r3/goal"
    assert not surface.can_move
    with pytest.raises(NoMoveTopic, match="r3: no move topic is bound"):
        surface.zero()


def test_surfaces_reads_every_robot_in_two_queries(django_assert_num_queries):
    for i in range(5):
        robot_with(f"q{i}", 1, move=(f"/q{i}/cmd_vel", "geometry_msgs/Twist"))
    with django_assert_num_queries(2):
        found = surfaces(Robot.objects.prefetch_related("bindings"))
    assert sorted(s.move_topic for s in found.values()) == [f"/q{i}/cmd_vel" for i in range(5)]
