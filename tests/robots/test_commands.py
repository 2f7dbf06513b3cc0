"""The command surface: what every publisher to a robot (executor, stops, teleop, watchdog, reconnect) sends."""

import pytest

from robots.commands import (
    NAV_MOVE_BASE,
    NAV_NAV2,
    NAV_SIMPLE,
    Call,
    CommandSurface,
    NoMoveTopic,
    surface_rows,
    surfaces,
)
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
    _zero, cancel = surface.zero()  # every goal of the action, whoever sent it: a zero goal id and stamp
    assert cancel == Call(
        "/navigate_to_pose/_action/cancel_goal",
        {"goal_info": {"goal_id": {"uuid": [0] * 16}, "stamp": {"sec": 0, "nanosec": 0}}},
    )
    assert surface.can_dock and surface.dock_namespace == "/dock"


def test_a_pose_stamped_goal_topic_and_a_robot_without_a_move_topic():
    simple = robot_with("r3", 1, navigate=("/r3/goal", "geometry_msgs/PoseStamped"))
    surface = CommandSurface.of(simple)
    assert surface.nav_kind == NAV_SIMPLE
    assert surface.simple_goal(1.0, 0.0, 0.0, 0.0)[0] == "/r3/goal"
    moving = CommandSurface.of(
        robot_with(
            "r4",
            1,
            move=("/r4/cmd_vel", "geometry_msgs/Twist"),
            navigate=("/r4/goal", "geometry_msgs/PoseStamped"),
        )
    )
    _zero, (topic, goal, _type) = moving.zero(here=(1.5, -2.0, 0.0))  # no cancel: a goal where it stands
    assert topic == "/r4/goal" and goal["pose"]["position"] == {"x": 1.5, "y": -2.0, "z": 0.0}
    assert not surface.can_move
    with pytest.raises(NoMoveTopic, match="r3: no move topic is bound"):
        surface.zero()


def test_surfaces_reads_every_robot_in_two_queries(django_assert_num_queries):
    for i in range(5):
        robot_with(f"q{i}", 1, move=(f"/q{i}/cmd_vel", "geometry_msgs/Twist"))
    with django_assert_num_queries(2):
        found = surfaces(Robot.objects.prefetch_related("bindings"))
    assert sorted(s.move_topic for s in found.values()) == [f"/q{i}/cmd_vel" for i in range(5)]


def test_speed_limits_nav2_in_percent_and_move_base_through_its_planners_max_vel_x():
    nav2 = robot_with(
        "n2",
        2,
        move=("/cmd_vel", "geometry_msgs/msg/Twist"),
        navigate=("/navigate_to_pose", "nav2_msgs/action/NavigateToPose"),
        speed_limit=("/speed_limit", "nav2_msgs/msg/SpeedLimit"),
    )
    surface = CommandSurface.of(nav2)
    assert surface.can_limit_speed and surface.read_speed() is None
    topic, message, type_ = surface.speed_limit(0.35, t=2.0)
    assert (topic, type_, message["percentage"], message["speed_limit"]) == (
        "/speed_limit",
        "nav2_msgs/msg/SpeedLimit",
        True,
        35.0,
    )
    assert surface.speed_limit(None)[1]["speed_limit"] == 0.0  # 0: no limit, as SpeedLimit.msg says
    mb = robot_with(
        "mb",
        1,
        move=("/cmd_vel", "geometry_msgs/Twist"),
        navigate=("/move_base", "move_base_msgs/MoveBaseAction"),
    )
    Binding.objects.filter(robot=mb, action="speed_limit").delete()
    Binding.objects.create(
        robot=mb,
        action="speed_limit",
        kind="service",
        target="/move_base/DWAPlannerROS/set_parameters",
        message_type="dynamic_reconfigure/Reconfigure",
    )
    surface = CommandSurface.of(mb)
    call = surface.speed_limit(0.5, top=0.5)
    assert call == Call(
        "/move_base/DWAPlannerROS/set_parameters",
        {"config": {"doubles": [{"name": "max_vel_x", "value": 0.25}]}},
    )
    assert surface.read_speed() == Call(
        "/move_base/DWAPlannerROS/set_parameters", {"config": {"doubles": []}}
    )
    assert not CommandSurface.of(
        robot_with("plain", 1, move=("/p/cmd_vel", "geometry_msgs/Twist"))
    ).can_limit_speed


def test_the_links_stop_socket_zeroes_a_nav2_robot_and_cancels_its_goal():
    """The links process's zero (the CLI stop's way) sends every command of the surface, the cancel call too
    (it once unpacked each as a publish and missed every nav2 robot)."""
    import asyncio

    from robots.links import LinkManager

    robot = robot_with(
        "n2",
        2,
        move=("/cmd_vel", "geometry_msgs/msg/TwistStamped"),
        navigate=("/navigate_to_pose/_action/send_goal", "nav2_msgs/action/NavigateToPose"),
    )

    class Client:
        is_connected = True
        sent: list = []

        async def publish(self, topic, message, type_):
            self.sent.append(("publish", topic))

        async def call_service(self, service, args, timeout):
            self.sent.append(("call", service))

    client, surface = Client(), CommandSurface.of(robot)

    async def stop():
        links = LinkManager(endpoints=[])
        links.links[robot.endpoint], links.targets = client, {"n2": surface}
        answer = await links.zero("all")
        await asyncio.sleep(0.05)  # the cancel's call is sent, not waited for
        return answer

    assert asyncio.run(stop()) == {"zeroed": ["n2"], "missed": {}, "unknown": []}
    assert client.sent == [("publish", "/cmd_vel"), ("call", "/navigate_to_pose/_action/cancel_goal")]


def test_surface_rows_read_no_json_column_and_no_row_twice(django_assert_num_queries):
    """What a stop's targets and a press's check read: two queries for any number of robots, no deferred field
    loaded afterwards (which would be one query per robot), the same surfaces as the full rows give."""
    for i in range(5):
        robot_with(
            f"s{i}",
            1,
            move=(f"/s{i}/cmd_vel", "geometry_msgs/Twist"),
            navigate=(f"/s{i}/goal", "geometry_msgs/PoseStamped"),
        )
    full = surfaces(Robot.objects.prefetch_related("bindings"))
    with django_assert_num_queries(2) as queries:
        rows = list(surface_rows(Robot.objects.all(), "max_linear"))
        found = surfaces(rows)
        limits = [row.max_linear for row in rows]
    assert found == full and len(limits) == 5
    assert not any(
        column in query["sql"]
        for query in queries.captured_queries
        for column in ("description", "candidates")
    )
