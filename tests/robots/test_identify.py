"""Topic identification on graphs built from tests/data/robot_profiles.yaml (a copy of the reference profiles: plain data, no server)."""

from pathlib import Path

import pytest
import yaml

from robots.discovery import Graph, TopicInfo
from robots.identify import Vocabulary, identify

PROFILES = yaml.safe_load((Path(__file__).resolve().parents[1] / "data" / "robot_profiles.yaml").read_text())[
    "robots"
]
TWIST, ODOM = "geometry_msgs/Twist", "nav_msgs/Odometry"


def make_graph(entries, actions=None, namespace="") -> Graph:
    """entries: (topic, type, publisher nodes, subscriber nodes)."""
    graph = Graph(url="ws://test:9090", namespace=namespace, actions=dict(actions or {}))
    for name, type_, pubs, subs in entries:
        graph.topics[name] = TopicInfo(name, type_, list(pubs), list(subs))
        for node in pubs:
            graph.nodes.setdefault(node, {"publishing": [], "subscribing": [], "services": []})[
                "publishing"
            ].append(name)
        for node in subs:
            graph.nodes.setdefault(node, {"publishing": [], "subscribing": [], "services": []})[
                "subscribing"
            ].append(name)
    return graph


def tiago_ros1(with_move_base=True) -> Graph:
    cmd = PROFILES["pal_tiago"]["ros1"]["cmd_vel"]
    controller = cmd["controller_topic"]["topic"]
    entries = [(controller, TWIST, ["/twist_mux"], ["/gazebo"])]
    for item in cmd["twist_mux_inputs"]:
        publisher = ["/move_base"] if item["name"] == "navigation" and with_move_base else []
        entries.append((item["topic"], TWIST, publisher, ["/twist_mux"]))
    entries.append((PROFILES["pal_tiago"]["ros1"]["odom"]["topic"], ODOM, ["/gazebo"], []))
    entries.append(("/ground_truth_odom", ODOM, ["/gazebo"], []))
    return make_graph(entries)


def husky_ros1() -> Graph:
    cmd = PROFILES["clearpath_husky"]["ros1"]["cmd_vel"]
    controller = cmd["controller_topic"]["topic"]
    entries = [(controller, TWIST, ["/twist_mux"], ["/husky_node"])]
    teleop = {
        "/joy_teleop/cmd_vel": "/joy_teleop/teleop_twist_joy",
        "/twist_marker_server/cmd_vel": "/twist_marker_server",
    }
    for item in cmd["input_topics_twist_mux"]:
        pubs = [teleop[item["topic"]]] if item["topic"] in teleop else []
        pubs += ["/move_base"] if item["topic"] == "/cmd_vel" else []
        entries.append((item["topic"], TWIST, pubs, ["/twist_mux"]))
    for odom in PROFILES["clearpath_husky"]["ros1"]["odom"]:
        entries.append(
            (
                odom["topic"],
                ODOM,
                ["/husky_node" if "controller" in odom["topic"] else "/ekf_localization"],
                [],
            )
        )
    return make_graph(entries)


def test_tiago_binds_the_navigation_input_of_twist_mux_not_the_controller():
    results = identify(tiago_ros1())
    assert results["move"].target == "/nav_vel"
    assert not results["move"].needs_user
    controller = next(
        c for c in results["move"].candidates if c["target"] == "/mobile_base_controller/cmd_vel"
    )
    assert controller["score"] < results["move"].candidates[0]["score"]
    assert results["odometry"].target == "/mobile_base_controller/odom"


def test_tiago_without_navigation_still_prefers_the_nav_input():
    assert identify(tiago_ros1(with_move_base=False))["move"].target == "/nav_vel"


def test_husky_binds_twist_mux_cmd_vel_and_wheel_odometry():
    results = identify(husky_ros1())
    assert (results["move"].target, results["move"].how) == ("/cmd_vel", "exact")
    assert results["odometry"].target == "/husky_velocity_controller/odom"


def test_a_tie_binds_nothing_and_keeps_the_candidates():
    graph = make_graph(
        [("/left_base/cmd_vel", TWIST, [], ["/left"]), ("/right_base/cmd_vel", TWIST, [], ["/right"])]
    )
    move = identify(graph)["move"]
    assert (move.target, move.needs_user) == ("", True)
    assert {c["target"] for c in move.candidates} == {"/left_base/cmd_vel", "/right_base/cmd_vel"}


def test_nothing_to_move_with_needs_a_person_but_a_missing_battery_does_not():
    results = identify(make_graph([("/odom", ODOM, ["/base"], [])]))
    assert results["move"].needs_user and results["move"].candidates == []
    assert not results["battery"].needs_user and results["battery"].target == ""


def test_a_velocity_topic_nobody_subscribes_is_not_a_candidate():
    results = identify(make_graph([("/cmd_vel", TWIST, ["/teleop"], [])]))
    assert results["move"].candidates == []


def test_ontology_synonym_finds_an_oddly_named_topic():
    graph = make_graph([("/base/drive", TWIST, [], ["/base"]), ("/base/state", ODOM, ["/base"], [])])
    vocab = Vocabulary()
    vocab.synonyms["move"] = {"drive"}
    move = identify(graph, vocab)["move"]
    assert (move.target, move.how) == ("/base/drive", "synonym")


def test_a_persons_choice_is_kept_while_its_target_exists():
    graph = husky_ros1()
    kept = identify(graph, user_choices={"move": "/kb_teleop/cmd_vel"})["move"]
    assert (kept.target, kept.how, kept.confidence) == ("/kb_teleop/cmd_vel", "user", 1.0)
    gone = identify(graph, user_choices={"move": "/no/longer/there"})["move"]
    assert (gone.target, gone.how) == ("/cmd_vel", "exact")


def test_namespaced_names_match_without_their_namespace():
    graph = make_graph(
        [("/robot7/cmd_vel", TWIST, [], ["/robot7/core"]), ("/robot7/odom", ODOM, ["/robot7/core"], [])],
        namespace="/robot7",
    )
    results = identify(graph)
    assert (results["move"].how, results["odometry"].how) == ("exact", "exact")


def test_ros2_navigation_binds_the_navigate_to_pose_action_over_goal_pose():
    graph = make_graph(
        [("/goal_pose", "geometry_msgs/msg/PoseStamped", [], ["/bt_navigator"])],
        actions={"/navigate_to_pose": "nav2_msgs/action/NavigateToPose", "/spin": "nav2_msgs/action/Spin"},
    )
    navigate = identify(graph)["navigate"]
    assert (navigate.target, navigate.kind, navigate.message_type) == (
        "/navigate_to_pose",
        "action",
        "nav2_msgs/action/NavigateToPose",
    )
    assert {c["target"] for c in navigate.candidates} == {"/navigate_to_pose", "/goal_pose"}


def test_a_create3_dock_action_server_binds_the_dock_role_and_not_navigate():
    graph = make_graph(
        [("/dock_status", "irobot_create_msgs/msg/DockStatus", ["/motion_control"], [])],
        actions={
            "/navigate_to_pose": "nav2_msgs/action/NavigateToPose",
            "/dock": "irobot_create_msgs/action/Dock",
            "/undock": "irobot_create_msgs/action/Undock",
        },
    )
    results = identify(graph)
    dock = results["dock"]
    assert (dock.target, dock.kind, dock.message_type, dock.how) == (
        "/dock",
        "action",
        "irobot_create_msgs/action/Dock",
        "exact",
    )
    assert [c["target"] for c in dock.candidates] == [
        "/dock"
    ]  # the status topic and Undock are not candidates
    assert results["navigate"].target == "/navigate_to_pose"


def test_a_robot_without_a_dock_leaves_the_dock_role_unbound_without_asking():
    dock = identify(husky_ros1())["dock"]
    assert (dock.target, dock.needs_user) == ("", False)


@pytest.mark.parametrize("n", [1200])
def test_identification_handles_a_big_graph(n):
    entries = [(f"/sensors/s{i}/value", "std_msgs/Float32", [f"/n{i % 50}"], []) for i in range(n)]
    entries += [("/cmd_vel", TWIST, [], ["/base"]), ("/odom", ODOM, ["/base"], [])]
    results = identify(make_graph(entries))
    assert (results["move"].target, results["odometry"].target) == ("/cmd_vel", "/odom")
