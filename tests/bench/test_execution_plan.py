"""The execution experiments' plain parts: lane targets, instruction JSON, trial limits, navigation bindings,
and the report's latency section and explanations."""

import math
from types import SimpleNamespace

import pytest

from bench import execution, report
from bench.run import latency_why
from experiments.probe import RobotLink


def link(name="robot1", cmd="/robot1/cmd_vel", start=(-4.5, -1.5, 0.0), v=0.22):
    return RobotLink(name, cmd, f"/{name}/odom", v, 2.84, "robots", "ws://x", start)


def test_lane_targets_alternate_forward_and_back_at_equal_distance():
    robot = link(start=(1.0, 2.0, math.pi / 2))
    forward, back = execution.lane(robot, 1), execution.lane(robot, 2)
    assert forward["x"] == pytest.approx(1.0)
    assert forward["y"] == pytest.approx(2.0 + execution.LEG_M)
    assert (back["x"], back["y"]) == pytest.approx((1.0, 2.0))
    assert execution.lane(robot, 3) == {**forward, "name": "robot1 lane 3"}


def test_lanes_parse_gives_each_robot_its_own_targets_in_turn():
    a, b = link(), link("robot2", "/robot2/cmd_vel", (-4.5, -0.9, 0.0))
    parse = execution.lanes_parse([a, b], 2)
    assert parse.valid and not parse.needs_user
    assert [(s["robots"], s["destination"]["name"]) for s in parse.steps] == [
        (["robot1"], "robot1 lane 1"),
        (["robot2"], "robot2 lane 1"),
        (["robot1"], "robot1 lane 2"),
        (["robot2"], "robot2 lane 2"),
    ]


def test_trial_limits_are_generous_and_shrink_with_the_time_scale():
    robot = link(v=1.0)
    real, fast = SimpleNamespace(time_scale=1.0), SimpleNamespace(time_scale=8.0)
    assert execution.trial_limit(real, robot, 5.0, nav=False) == pytest.approx(3 * 5.0 / 1.0 + 10 + 3)
    assert execution.trial_limit(real, robot, 5.0, nav=True) > execution.trial_limit(real, robot, 5.0, False)
    assert execution.trial_limit(fast, robot, 5.0, nav=False) < execution.trial_limit(real, robot, 5.0, False)


@pytest.mark.django_db
def test_set_navigation_binds_the_namespaced_move_base_and_unbinds_it():
    from robots.models import Binding, Robot

    Robot.objects.create(name="robot1", endpoint="ws://x")
    Robot.objects.create(name="husky", endpoint="ws://y")
    links = [link(), link("husky", "/husky_velocity_controller/cmd_vel")]
    execution.set_navigation(links, True)
    targets = dict(Binding.objects.filter(action="navigate").values_list("robot__name", "target"))
    assert targets == {"robot1": "/robot1/move_base/goal", "husky": "/move_base/goal"}
    execution.set_navigation(links, False)
    assert not Binding.objects.filter(action="navigate").exists()


def test_success_why_lists_the_failed_trials_only_when_a_rate_is_missed():
    ok = [{"text": "shift husky to D", "status": "succeeded", "outcome": "", "error": ""}]
    assert execution.success_why({"no_nav": 1.0, "nav": 1.0}, ok, 8.0) == ""
    bad = [*ok, {"text": "shift husky to E", "status": "running", "outcome": "no final status", "error": ""}]
    text = execution.success_why({"no_nav": 0.5, "nav": 1.0}, bad, 8.0)
    assert "'shift husky to E': no final status" in text
    assert "shift husky to D" not in text


def test_latency_why_is_empty_when_the_goals_are_met_and_names_the_cost_otherwise():
    assert latency_why({"1": {"p99": 10.0}, "100": {"p99": 40.0}}, 1.0) == ""
    text = latency_why({"1": {"p99": 30.0}, "100": {"p99": 400.0}}, 2.5)
    assert "2.5 ms" in text and "400.0 ms" in text


def test_the_latency_section_shows_both_paths_the_bare_relay_and_their_ratios():
    summary = report.build_summary(
        {
            "latency": {
                "summary": {
                    "direct_latency_ms": {"1": {"p50": 2.0, "p99": 4.0}},
                    "command_latency_ms": {"1": {"p50": 10.0, "p99": 40.0}},
                    "relay_latency_ms": {"1": {"p50": 3.0, "p99": 6.0}},
                    "stop_latency_ms": {"p50": 30.0, "p99": 60.0, "robots": 5, "queued": 90},
                }
            }
        }
    )
    text = "\n".join(report.render_latency(summary))
    assert (
        "| 1 | 2.00 / 4.0 | 10.00 / 40.0 | 5.00 | 10.00 | 3.00 / 6.0 | 1.50 |" in text
    )  # and the bare relay's
    assert "| 100 | – / – | – / – | – | – | – / – | – |" in text
    assert "90 instructions still queued" in text
