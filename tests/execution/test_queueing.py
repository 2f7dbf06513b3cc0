"""Per-robot queues: instructions run in order; a work instruction preempts a motion; stop gets through."""

import math

import pytest

from execution.instructions import submit
from execution.models import Execution, Instruction
from tests.execution.helpers import parse, step, transitions, wait_final, wait_for

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]


def test_three_sequential_instructions_to_one_robot_run_in_order(turtle_world, fleet_admin):
    goals = [(-1.7, -0.5), (-1.7, -0.2), (-2.0, -0.2)]
    instructions = [
        submit(f"move turtlebot to P{i}", fleet_admin, parse=parse(step(["turtlebot"], x, y, f"P{i}")))
        for i, (x, y) in enumerate(goals)
    ]
    finished = [wait_final(instruction) for instruction in instructions]
    assert [i.status for i in finished] == ["succeeded"] * 3
    assert finished[0].finished_at < finished[1].motion_started_at
    assert finished[1].finished_at < finished[2].motion_started_at
    moves = [reason for _, to, reason, _ in transitions("turtlebot") if to == "motion"]
    assert moves == ["moving to P0", "moving to P1", "moving to P2"]
    x, y, _ = turtle_world.pose("turtlebot")
    assert math.dist((x, y), goals[-1]) < 0.15
    assert Execution.objects.filter(status="succeeded").count() == 3


def test_a_work_instruction_preempts_a_motion_which_then_resumes(turtle_world, fleet_admin):
    move = submit("move turtlebot to Q", fleet_admin, parse=parse(step(["turtlebot"], -0.9, -0.5, "Q")))
    wait_for(lambda: Instruction.objects.get(pk=move.pk).motion_started_at, what="motion")
    rotate = submit(
        "rotate turtlebot once",
        fleet_admin,
        parse=parse(step(["turtlebot"], task="rotate(1)", action="rotate")),
    )
    rotate, move = wait_final(rotate), wait_final(move)
    assert (rotate.status, move.status) == ("succeeded", "succeeded")
    assert rotate.finished_at < move.finished_at
    sequence = [(frm, to, iid) for frm, to, _, iid in transitions("turtlebot")]
    assert sequence[-5:] == [
        ("motion", "ready", move.pk),  # preempted
        ("ready", "work", rotate.pk),
        ("work", "ready", rotate.pk),
        ("ready", "motion", move.pk),  # resumed
        ("motion", "ready", move.pk),
    ]
    x, y, _ = turtle_world.pose("turtlebot")
    assert math.dist((x, y), (-0.9, -0.5)) < 0.15


def test_a_motion_instruction_does_not_preempt_a_motion(turtle_world, fleet_admin):
    first = submit("move turtlebot to R", fleet_admin, parse=parse(step(["turtlebot"], -1.6, -0.5, "R")))
    wait_for(lambda: Instruction.objects.get(pk=first.pk).motion_started_at, what="motion")
    second = submit("move turtlebot to S", fleet_admin, parse=parse(step(["turtlebot"], -1.6, -0.2, "S")))
    first, second = wait_final(first), wait_final(second)
    assert first.finished_at < second.motion_started_at
    assert not any(to == "ready" and "preempted" in reason for _, to, reason, _ in transitions("turtlebot"))


def test_stop_during_motion_reaches_the_command_topic_within_one_odometry_period(turtle_world, fleet_admin):
    sim = turtle_world
    move = submit("move turtlebot far", fleet_admin, parse=parse(step(["turtlebot"], 0.5, -0.5, "far")))
    wait_for(lambda: sim.call(lambda: sim.fleet.robots["turtlebot"].body.vx) > 0.1, what="driving")
    stop = submit("stop", fleet_admin, parse=parse(step("all", action="stop")))
    stopped_at = sim.call(lambda: sim.fleet.physics.time)
    period = sim.fleet.odom_period
    wait_for(
        lambda: sim.call(lambda: sim.fleet.physics.time) >= stopped_at + period, what="one odometry period"
    )
    command = sim.call(lambda: sim.fleet.robots["turtlebot"].body.cmd)
    assert (command.vx, command.wz) == (0.0, 0.0)
    assert command.stamp <= stopped_at + period
    assert stop.status == "succeeded" and "turtlebot: stopped" in stop.outcome
    move = wait_final(move)
    assert move.status == "cancelled"
    settled = sim.pose("turtlebot")
    wait_for(lambda: sim.call(lambda: sim.fleet.physics.time) >= stopped_at + 1.0, what="one second")
    assert math.dist(settled[:2], sim.pose("turtlebot")[:2]) < 0.01  # nobody drives it again
    assert transitions("turtlebot")[-1][:3] == ("motion", "ready", "stopped")
