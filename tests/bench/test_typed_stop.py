"""The typed-stop experiment's plain parts: its instruction JSON, what counts as moving, the result it builds,
the report's section and goals, and the silent endpoint that stands for an unreachable robot."""

import asyncio
import socket

import pytest

from bench import report, typed_stop
from experiments.probe import RobotLink

# (p50, p99, missing, moving, stops, answered_ms) per kind of stop: made up, no timing is asserted
KINDS = {
    "typed_socket": (4.0, 9.0, 0, 20, 20, 80.0),
    "typed": (14.0, 29.0, 0, 20, 20, 90.0),
    "typed_one": (3.5, 7.5, 0, 19, 20, 40.0),
    "socket": (2.0, 5.0, 0, 20, 20, None),
    "stop_all": (30.0, 60.0, 1, 20, 20, 70.0),
}


def kind(p50, p99, missing, moving, stops, answered):
    return {
        "n": stops - missing,
        "p50": p50,
        "p99": p99,
        "missing": missing,
        "moving": moving,
        "stops": stops,
        "answered_ms": answered,
        "answered_p99_ms": answered,
        "said": [],
    }


def synthetic(unreachable_p99=12.0):
    reachable = {name: kind(*values) for name, values in KINDS.items()}
    unreachable = {name: kind(*KINDS[name]) for name in typed_stop.UNREACHABLE_KINDS}
    unreachable["typed_socket"] = kind(5.0, unreachable_p99, 0, 20, 20, 2100.0)
    unreachable["typed"]["said"] = ['2x {"text": "stop"} -> HTTP 201 failed: unreachable1: cannot reach']
    for phase in (reachable, unreachable):
        phase["first_typed"] = kind(300.0, 310.0, 0, 0, 10, 320.0)
        phase["floor"] = {"answered_ms": 3.0, "answered_p99_ms": 6.0}
    return typed_stop.typed_stop_result(reachable, unreachable, 10, 3, 4)


def test_the_rotate_instruction_is_one_robot_turning_and_passes_the_step_contract():
    parse = typed_stop.rotate_parse("husky")
    (step,) = parse.checked()
    assert (step.action, step.robots.names, step.task) == (
        "rotate",
        ("husky",),
        f"rotate({typed_stop.TURNS})",
    )
    assert parse.valid and not parse.needs_user


def test_a_robot_is_moving_only_for_a_non_zero_command_in_the_window():
    robot = RobotLink("robot1", "/robot1/cmd_vel", "/robot1/odom", 0.22, 2.84, "robots")
    reception = typed_stop.Reception.__new__(typed_stop.Reception)
    reception.times = {("robots", "/robot1/cmd_vel"): [(10.0, 0.0, 0.0), (11.0, 0.0, 1.2), (12.0, 0.0, 0.0)]}
    assert typed_stop.moving_between(reception, robot, 10.5, 11.5)
    assert not typed_stop.moving_between(reception, robot, 11.5, 13.0)  # only a zero in it
    assert not typed_stop.moving_between(reception, robot, 9.0, 11.0)  # the window ends before 11.0


def test_samples_say_how_many_stops_found_no_zero_and_no_motion():
    samples = typed_stop.Samples(ms=[4.0, None, 6.0], moving=[True, True, False], answered_ms=[50.0])
    out = samples.summary()
    assert (out["n"], out["missing"], out["moving"], out["stops"]) == (2, 1, 2, 3)
    assert out["p50"] == 5.0 and out["answered_ms"] == 50.0
    assert out["ms"] == [4.0, None, 6.0]


def test_what_the_portal_said_keeps_only_the_robots_it_did_not_stop():
    data = {
        "status": "failed",
        "outcome": "husky: stopped; unreachable1: cannot reach ws://x; robot1: stopped",
    }
    text = typed_stop.gist({"text": "stop"}, 201, data)
    assert text == '{"text": "stop"} -> HTTP 201 failed: unreachable1: cannot reach ws://x'


def test_the_result_carries_the_summary_key_and_the_typed_over_socket_ratio():
    result = synthetic()
    summary = result["summary"]["typed_stop_latency_ms"]
    assert (summary["p50"], summary["p99"], summary["robots"]) == (4.0, 9.0, 10)
    assert summary["unreachable"] == {"p50": 5.0, "p99": 12.0}
    assert summary["socket"] == {"p50": 2.0, "p99": 5.0}
    assert summary["ratio_p50"] == 2.0
    assert result["missed"] == ""
    assert "accepts and never answers" in " ".join(result["notes"])


def test_a_missed_goal_is_explained_with_the_figures():
    result = synthetic(unreachable_p99=2100.0)
    assert "with an unreachable robot registered p99 2100.0 ms" in result["missed"]
    assert "answered in p50 3.0 ms" in result["missed"]
    assert "fast_stop.py" in result["missed"]


def test_the_summary_and_goals_know_the_typed_stop(tmp_path):
    summary = report.write_all({"typed_stop": synthetic(unreachable_p99=30.0)}, tmp_path, "quick")
    assert summary["typed_stop_latency_ms"]["one_robot"] == {"p50": 3.5, "p99": 7.5}
    verdicts = {row["key"]: row["verdict"] for row in report.goal_rows(summary)}
    assert verdicts["typed_stop_latency_ms.p99"] == "met"
    assert verdicts["typed_stop_latency_ms.unreachable.p99"] == "MISSED"


def test_the_report_section_shows_every_kind_with_and_without_the_unreachable_robot(tmp_path):
    report.write_all({"typed_stop": synthetic()}, tmp_path, "quick")
    text = (tmp_path / "REPORT.md").read_text()
    assert "## Typed stop: the console against the STOP buttons (same run)" in text
    assert (
        f"| {typed_stop.KINDS['typed_socket']} | 4.0 / 9.0 | 5.0 / 12.0 | 2.00 | 80.0 | 0 / 0 of 20 |" in text
    )
    assert f"| {typed_stop.KINDS['typed']} | 14.0 / 29.0 | 14.0 / 29.0 | 7.00 | 90.0 | 0 / 0 of 20 |" in text
    assert f"| {typed_stop.KINDS['stop_all']} | 30.0 / 60.0 | – | 15.00 | 70.0 | 1 / 0 of 20 |" in text
    assert f"| {typed_stop.KINDS['typed_one']} | 3.5 / 7.5 | 3.5 / 7.5 | 1.75 | 40.0 | 0 / 1 of 20 |" in text
    assert "**met** (p99 9.0 ms; 12.0 ms with the unreachable robot)" in text
    assert "warm-up: the phase's first typed stop, robots idle: p50 300.0 ms" in text
    assert "answered in p50 3.0 ms, p99 6.0 ms" in text
    assert "typed (unreachable robot registered) answered: 2x" in text


def test_without_a_run_the_section_says_not_measured():
    lines = report.render_typed_stop(report.build_summary({}), None)
    assert any("**not measured**" in line for line in lines)


def test_the_silent_endpoint_accepts_and_never_answers():
    async def probe():
        async with typed_stop.SilentEndpoint() as silent:
            port = int(silent.url.rsplit(":", 1)[1])
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            writer.write(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\r\n")
            await writer.drain()
            with pytest.raises(TimeoutError):
                await asyncio.wait_for(reader.read(1), 0.3)
            accepted = silent.accepted
            writer.close()
        return port, accepted

    port, accepted = asyncio.run(probe())
    assert accepted == 1
    with pytest.raises(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
        pass  # closed with the block


@pytest.mark.django_db
def test_robots_on_endpoints_the_world_does_not_serve_are_unregistered_and_counted():
    from robots.models import Binding, Robot

    kept = Robot.objects.create(name="robot1", endpoint="ws://served")
    gone = Robot.objects.create(name="robot8", endpoint="ws://stopped")
    Binding.objects.create(
        robot=gone, action="move", target="/robot8/cmd_vel", message_type="geometry_msgs/Twist"
    )
    assert typed_stop.forget_others(["ws://served"]) == 1  # robots, not their bindings
    assert list(Robot.objects.values_list("name", flat=True)) == [kept.name]
