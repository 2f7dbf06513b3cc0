"""Registration end to end: the demo world, failing endpoints, re-registration, a person's choice, --json, the API."""

import json
from io import StringIO

import pytest
from django.core.management import CommandError, call_command

from execution.models import TimeSlot
from fleetcore.bindings import ROLES
from robots.binding import choose
from robots.models import Binding, RegistrationRecord, Robot, Topic
from robots.registration import register_endpoints
from tests.robots.fakes import HttpServer, OddServer, free_port, nav2_robot, robot_graph

pytestmark = [pytest.mark.timeout(60), pytest.mark.django_db]

DEMO = ("robots", "turtlebot", "husky", "tiago")


def bound(robot: Robot, action: str) -> str:
    return robot.bindings.get(action=action).target


def test_demo_world_registers_seven_robots_with_move_odometry_and_wheels(paper_world):
    from places.worlds import load_world_into_db

    load_world_into_db("paper")
    results = register_endpoints([paper_world.urls[k] for k in DEMO])
    assert all(r.ok for r in results), [r.error for r in results]
    robots = {r.name: r for r in Robot.objects.all()}
    assert set(robots) == {"turtlebot", "husky", "tiago", "robot1", "robot2", "robot3", "robot4"}
    expected = {
        "turtlebot": ("/cmd_vel", "/odom", 2),
        "husky": ("/cmd_vel", "/odometry/filtered", 4),
        "tiago": ("/nav_vel", "/mobile_base_controller/odom", 2),
        **{f"robot{i}": (f"/robot{i}/cmd_vel", f"/robot{i}/odom", 2) for i in range(1, 5)},
    }
    for name, (move, odom, wheels) in expected.items():
        robot = robots[name]
        assert (bound(robot, "move"), bound(robot, "odometry"), robot.wheel_count) == (move, odom, wheels), (
            name
        )
        assert robot.link_status == Robot.Link.ONLINE
    assert robots["robot3"].namespace == "/robot3"
    assert robots["husky"].model == "husky" and robots["husky"].max_linear == 1.0
    assert robots["tiago"].start_pose == pytest.approx([0.0, -3.0, 1.5708], abs=1e-3)
    assert robots["turtlebot"].start_pose == pytest.approx(
        [-2.0, -0.5, 0.0], abs=1e-3
    )  # no amcl: spawn param
    assert bound(robots["robot1"], "navigate") == "/robot1/move_base"
    assert TimeSlot.objects.filter(robot__name="tiago").count() == 3  # Table 12 slots attached


def test_ros2_and_legged_robots_register(paper_world):
    register_endpoints([paper_world.urls["tb3_nav2"], paper_world.urls["spot"]])
    nav2, spot = Robot.objects.get(name="tb3_nav2"), Robot.objects.get(name="spot")
    assert (nav2.ros_version, bound(nav2, "navigate")) == (2, "/navigate_to_pose")
    assert nav2.bindings.get(action="navigate").kind == Binding.Kind.ACTION
    dock = nav2.bindings.get(action="dock")
    assert (dock.target, dock.kind, dock.message_type, dock.needs_user) == (
        "/dock",
        Binding.Kind.ACTION,
        "irobot_create_msgs/action/Dock",
        False,
    )
    assert spot.bindings.get(action="dock").target == ""  # no dock station: nothing to bind, nothing to ask
    assert (spot.drive, spot.leg_count, spot.wheel_count) == ("legged", 4, 0)
    assert bound(spot, "move") == "/spot/cmd_vel"


def test_failing_endpoints_give_one_line_errors_while_the_others_register(endpoint):
    good = endpoint()
    with OddServer("garbage") as garbage, OddServer("silent") as silent, HttpServer() as http:
        down = f"ws://127.0.0.1:{free_port()}"
        results = register_endpoints([good.url, down, garbage.url, silent.url, http.url], call_timeout=0.5)
    by_url = {r.url: r for r in results}
    assert by_url[good.url].ok and by_url[good.url].robots == ["fakebot"]
    # closed port, garbage, silence and plain HTTP read alike: the errors never tell which ports are open
    for url in (down, garbage.url, silent.url, http.url):
        assert by_url[url].error == f"{url}: unreachable (no rosbridge server answered)"
    assert RegistrationRecord.objects.filter(ok=False).count() == 4


def test_reregistration_updates_in_place_and_records_what_changed(endpoint):
    ep = endpoint()
    register_endpoints([ep.url])
    robot = Robot.objects.get(name="fakebot")
    assert bound(robot, "scan") == "/scan"

    def change(graph):
        graph.node("/laser").pubs.discard("/scan")
        graph.add_publisher("/bumper", "/bumper", "std_msgs/Bool")

    ep.mutate(change)
    (result,) = register_endpoints([ep.url])
    assert Robot.objects.count() == 1 and Robot.objects.get().pk == robot.pk
    assert set(Topic.objects.filter(robot=robot).values_list("name", flat=True)) == {
        "/cmd_vel",
        "/odom",
        "/bumper",
    }
    changes = RegistrationRecord.objects.get(pk=result.record_id).changes["fakebot"]
    assert changes["topics_added"] == ["/bumper"] and changes["topics_removed"] == ["/scan"]
    assert changes["bindings_changed"] == {"scan": ["/scan", ""]}
    assert Binding.objects.filter(robot=robot).count() == len(ROLES)  # one row per binding role, bound or not


def test_a_persons_choice_survives_reregistration_while_its_target_exists(endpoint, fleet_admin):
    def two_inputs(graph):
        robot_graph(graph)
        graph.add_subscriber("/base_driver", "/teleop/cmd_vel", "geometry_msgs/Twist")

    ep = endpoint(build=two_inputs)
    register_endpoints([ep.url])
    robot = Robot.objects.get(name="fakebot")
    assert bound(robot, "move") == "/cmd_vel"
    choose(robot, "move", "/teleop/cmd_vel", fleet_admin)
    register_endpoints([ep.url])
    move = robot.bindings.get(action="move")
    assert (move.target, move.how) == ("/teleop/cmd_vel", "user")

    ep.mutate(lambda g: g.node("/base_driver").subs.discard("/teleop/cmd_vel"))
    (result,) = register_endpoints([ep.url])
    assert (bound(robot, "move"), robot.bindings.get(action="move").how) == ("/cmd_vel", "exact")
    assert result.changes["fakebot"]["user_choices_dropped"] == ["move: /teleop/cmd_vel"]


def test_same_urdf_name_on_two_endpoints_gets_distinct_robot_names(endpoint):
    first, second = endpoint(), endpoint()
    register_endpoints([first.url, second.url])
    names = sorted(Robot.objects.values_list("name", flat=True))
    assert names == ["fakebot", "fakebot_2"]  # never host:port in a name people type


def test_register_command_json_shape(endpoint):
    ep = endpoint()
    out = StringIO()
    call_command("register", ep.url, "--json", stdout=out)
    (robot,) = json.loads(out.getvalue())
    assert set(robot) == {
        "name",
        "endpoint",
        "namespace",
        "model",
        "drive",
        "wheels",
        "ros_version",
        "bindings",
        "needs_user",
    }
    assert robot["bindings"]["move"] == {
        "topic": "/cmd_vel",
        "type": "geometry_msgs/Twist",
        "how": "exact",
        "confidence": 1.0,
    }
    assert (robot["wheels"], robot["drive"], robot["needs_user"]) == (2, "wheeled", [])


def test_register_command_fails_only_if_an_endpoint_failed(endpoint):
    ep = endpoint()
    err = StringIO()
    with pytest.raises(CommandError, match="1 of 2 endpoints failed"):
        call_command("register", ep.url, f"ws://127.0.0.1:{free_port()}", stdout=StringIO(), stderr=err)
    assert "unreachable" in err.getvalue()
    assert Robot.objects.filter(name="fakebot").exists()


def test_api_register_inline_needs_the_register_permission(endpoint, client_for, fleet_admin, viewer):
    ep = endpoint()
    body = {"endpoints": [ep.url], "wait": True}
    denied = client_for(viewer).post("/api/robots/register", body, content_type="application/json")
    assert denied.status_code == 403
    ok = client_for(fleet_admin).post("/api/robots/register", body, content_type="application/json")
    assert ok.status_code == 200
    assert ok.json()["results"][0]["robots"] == ["fakebot"]


def test_an_endpoint_with_1200_topics_registers(endpoint):
    from tests.robots.fakes import big_graph

    ep = endpoint(build=big_graph)
    (result,) = register_endpoints([ep.url])
    robot = Robot.objects.get(name="bigbot")
    assert result.ok and robot.topics.count() == 1200
    assert (bound(robot, "move"), bound(robot, "odometry")) == ("/cmd_vel", "/odom")


NAV2_MAKERS = {  # ROS 2 robots of makers not in the profiles, as their nav2 bringups name things
    "scout_mini": lambda g: nav2_robot(g, "", "scout_mini"),  # AgileX: /cmd_vel, /odom
    "mpo_700": lambda g: [nav2_robot(g, ns, "mpo_700") for ns in ("/robot0", "/robot1")],  # Neobotix, a pair
    "summit_xl": lambda g: nav2_robot(
        g, "", "summit_xl", "robotnik_base_control/cmd_vel", "robotnik_base_control/odom"
    ),
}


def test_ros2_nav2_robots_of_other_makers_bind_the_actions_and_the_speed_limit(endpoint):
    eps = {maker: endpoint(ros_version=2, build=build) for maker, build in NAV2_MAKERS.items()}
    results = register_endpoints([ep.url for ep in eps.values()])
    assert all(r.ok for r in results), [r.error for r in results]
    robots = {(r.endpoint, r.namespace): r for r in Robot.objects.all()}
    expected = {
        (eps["scout_mini"].url, ""): ("", "/cmd_vel"),
        (eps["mpo_700"].url, "/robot0"): ("/robot0", "/robot0/cmd_vel"),
        (eps["mpo_700"].url, "/robot1"): ("/robot1", "/robot1/cmd_vel"),
        (eps["summit_xl"].url, ""): ("", "/robotnik_base_control/cmd_vel"),
    }
    assert set(robots) == set(expected)
    for key, (ns, move) in expected.items():
        robot = robots[key]
        navigate = robot.bindings.get(action="navigate")
        assert (navigate.target, navigate.kind, navigate.message_type) == (
            f"{ns}/navigate_to_pose",
            Binding.Kind.ACTION,
            "nav2_msgs/action/NavigateToPose",
        ), key  # the action, not /goal_pose beside it
        assert bound(robot, "speed_limit") == f"{ns}/speed_limit"
        assert (bound(robot, "move"), bound(robot, "battery")) == (move, f"{ns}/battery_state")
        assert robot.ros_version == 2


def test_nav_stacks_bind_their_speed_limits(paper_world):
    register_endpoints([paper_world.urls[k] for k in ("tb3_nav2", "husky", "tiago", "spot")])
    limits = {robot.name: robot.bindings.get(action="speed_limit") for robot in Robot.objects.all()}
    assert (limits["tb3_nav2"].target, limits["tb3_nav2"].message_type) == (
        "/speed_limit",
        "nav2_msgs/msg/SpeedLimit",
    )
    assert (limits["husky"].target, limits["husky"].kind) == (
        "/move_base/DWAPlannerROS/set_parameters",
        "service",
    )
    assert limits["tiago"].target == "/move_base/TebLocalPlannerROS/set_parameters"
    assert (limits["spot"].target, limits["spot"].needs_user) == (
        "",
        False,
    )  # no nav stack: the portal drives
    nav2 = Robot.objects.get(name="tb3_nav2")
    assert bound(nav2, "battery") == "/battery_state"


def test_an_endpoint_of_many_robots_is_stored_in_a_few_queries_per_robot(django_assert_max_num_queries):
    """Its robots' rows (topics, nodes, services, params, bindings) go in one insert per kind for the whole
    endpoint: each robot costs its own save only, and every robot gets the rows it would get alone."""
    from simworker.testing import running_world

    with running_world("paper", extra=30, endpoints=["extra"]) as sim:
        with django_assert_max_num_queries(2 * 30 + 40):  # was about 8 a robot: a round trip per kind
            (result,) = register_endpoints([sim.urls["extra"]])
        assert result.ok, result.error
        (again,) = register_endpoints([sim.urls["extra"]])  # re-registration: rows compared, nothing changes
    robots = Robot.objects.filter(name__startswith="robot").order_by("pk")
    assert robots.count() == 30 and sorted(result.robots) == sorted(r.name for r in robots)
    for robot in robots:
        assert (
            bound(robot, "move") == f"/{robot.name}/cmd_vel"
            and bound(robot, "odometry") == f"/{robot.name}/odom"
        )
        assert robot.topics.filter(name=f"/{robot.name}/odom").exists()
    per_robot = {robot.topics.count() for robot in robots}
    assert len(per_robot) == 1 and per_robot.pop() > 3  # every robot got its whole graph
    assert again.ok and not again.changes  # stored whole the first time: nothing to add
