"""The experiments page and its runs: validation, confirmation, permissions."""

import pytest

from experiments.models import ExperimentRun
from experiments.runs import ExperimentError, robot_link, start_run
from robots.models import Binding, Robot


@pytest.fixture
def robot(db):
    """A registered robot with its move and odometry bound."""
    robot = Robot.objects.create(name="tb", endpoint="ws://127.0.0.1:1", max_linear=0.22, max_angular=2.84)
    Binding.objects.create(robot=robot, action="move", target="/cmd_vel", message_type="geometry_msgs/Twist")
    Binding.objects.create(robot=robot, action="odometry", target="/odom", message_type="nav_msgs/Odometry")
    return robot


def test_a_confirmed_run_is_stored_queued_with_its_robots(robot, operator):
    run = start_run("response", [robot], operator, {"trials": 2}, confirmed=True)
    assert run.status == "queued"
    assert list(run.robots.all()) == [robot]
    assert run.params["trials"] == 2


@pytest.mark.parametrize(
    ("kind", "robots", "params", "confirmed", "message"),
    [
        ("dance", True, {}, True, "kind: expected one of"),
        ("response", False, {}, True, "choose at least one robot"),
        ("response", True, {}, False, "will move"),
        ("success", True, {"trials": 0}, True, "trials: a whole number"),
        ("success", True, {"trials": "3"}, True, "trials: a whole number"),
    ],
)
def test_bad_runs_are_refused_with_a_reason(robot, operator, kind, robots, params, confirmed, message):
    with pytest.raises(ExperimentError, match=message):
        start_run(kind, [robot] if robots else [], operator, params, confirmed)
    assert not ExperimentRun.objects.exists()


def test_robot_link_uses_the_bindings_and_names_what_is_missing(robot):
    link = robot_link(robot)
    assert (link.cmd_topic, link.odom_topic, link.max_linear) == ("/cmd_vel", "/odom", 0.22)
    robot.bindings.filter(action="odometry").delete()
    with pytest.raises(ExperimentError, match="no odometry binding"):
        robot_link(robot)


def test_the_page_lists_runs_and_a_viewer_cannot_start_one(client_for, viewer, robot, operator):
    start_run("response", [robot], operator, {"trials": 1}, confirmed=True)
    from django.test import RequestFactory

    from portal.views_experiments import experiments

    request = RequestFactory().post(
        "/experiments/", {"kind": "response", "robots": [robot.pk], "confirm": "yes"}
    )
    request.user = viewer
    from django.core.exceptions import PermissionDenied

    with pytest.raises(PermissionDenied):
        experiments(request)
    assert ExperimentRun.objects.count() == 1
