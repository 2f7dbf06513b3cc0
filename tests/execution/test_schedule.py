"""Schedules (the paper's Tables 2 and 12): slots run by themselves; people are refused inside a slot."""

import datetime
import time

import pytest
from django.utils import timezone

from execution import coordination, scheduler
from execution.control import stop
from execution.instructions import submit
from execution.models import Execution, Instruction, TimeSlot
from robots.models import Robot
from tests.execution.helpers import parse, step, wait_final, wait_for

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]

TABLE_12 = {
    "turtlebot": [("08:00", "A", "rotate(5)"), ("12:00", "B", "rotate(5)"), ("14:00", "C", "rotate(5)")],
    "husky": [("08:00", "D", "rotate(10)"), ("10:00", "E", "rotate(10)"), ("14:00", "F", "rotate(10)")],
    "tiago": [("10:00", "G", "rotate(15)"), ("12:00", "H", "rotate(15)"), ("14:00", "I", "rotate(15)")],
}


def at(hhmm: str) -> datetime.datetime:
    return timezone.make_aware(
        datetime.datetime.combine(timezone.localdate(), datetime.time.fromisoformat(hhmm))
    )


def test_table_12_slots_start_by_themselves_in_order_on_a_compressed_clock(table12_world):
    assert TimeSlot.objects.filter(enabled=True).count() == 9
    clock = scheduler.Clock(at("07:59:58"), scale=4800.0)  # two hours in a second and a half
    running_at_once = []
    while clock.now() < at("16:00"):
        scheduler.tick(clock)
        for robot in Robot.objects.all():
            running_at_once.append(Execution.objects.filter(robot=robot, status="running").count())
        time.sleep(0.1)
    started = Instruction.objects.filter(source="schedule").order_by("received_at", "pk")
    per_robot = {}
    for instruction in started:
        (s,) = instruction.parse["steps"]
        per_robot.setdefault(s["robots"][0], []).append((s["destination"]["name"], s["task"]))
    assert per_robot == {name: [(goal, task) for _, goal, task in slots] for name, slots in TABLE_12.items()}
    assert max(running_at_once) == 1  # one active instruction per robot, the others queue behind it
    # On this clock a robot's next slot preempts the one before within 1.5 s, before it has driven much; the
    # slot running at the end is the one that must get moving.
    last = {name: started.filter(parse__steps__0__robots=[name]).last() for name in TABLE_12}
    for name, instruction in last.items():
        wait_for(  # a robot may first wait for another's reserved path (execution.traffic): a generous deadline
            lambda i=instruction: Instruction.objects.get(pk=i.pk).motion_started_at,
            timeout=60.0,
            what=f"{name} moving",
        )
    assert scheduler.run_due_slots(at("15:00")) == []  # each slot runs once a day
    stop(list(TABLE_12), None)
    for instruction in started:
        assert wait_final(instruction).status == "cancelled"


def test_an_instruction_to_a_robot_inside_its_slot_is_refused_with_the_slot_named(table12_world, fleet_admin):
    now = timezone.localtime()
    slot = TimeSlot.objects.filter(robot__name="husky").first()
    slot.start = (now - datetime.timedelta(minutes=1)).time()
    slot.end = (now + datetime.timedelta(minutes=5)).time()
    if slot.start >= slot.end:
        pytest.skip("too close to midnight for a slot around now")
    TimeSlot.objects.filter(robot__name="husky").exclude(pk=slot.pk).update(enabled=False)
    slot.save()
    instruction = submit("move husky to A", fleet_admin, parse=parse(step(["husky"], 2.0, 2.0, "A")))
    assert instruction.status == "refused"
    assert f"{slot.start:%H:%M}-{slot.end:%H:%M} ({slot.goal.name} + {slot.task})" in instruction.outcome
    assert f"free from {slot.end:%H:%M}" in instruction.outcome
    assert not Execution.objects.filter(instruction=instruction).exists()


def test_unknown_robot_and_missing_robot_are_refused_in_words(table12_world, fleet_admin):
    unknown = submit("move r2d2 to A", fleet_admin, parse=parse(step(["r2d2"], 2.0, 2.0, "A")))
    assert (unknown.status, unknown.outcome) == ("refused", "No robot named r2d2 is registered.")
    nobody = submit("move to A", fleet_admin, parse=parse(step([], 2.0, 2.0, "A")))
    assert nobody.status == "refused" and "which robot" in nobody.outcome


def test_a_robot_held_by_another_operator_is_refused(table12_world, operator, second_operator):
    from access.leases import take

    TimeSlot.objects.filter(robot__name="tiago").update(enabled=False)  # free at any hour the test runs
    take(second_operator, Robot.objects.get(name="tiago"))
    instruction = submit("move tiago to G", operator, parse=parse(step(["tiago"], 1.0, -1.0, "G")))
    assert instruction.status == "refused"
    assert "held by olga" in instruction.outcome
    tiago = Robot.objects.get(name="tiago").pk
    assert coordination.lock_holders([tiago])[tiago] is None


class FakeTime:
    """time.monotonic and time.sleep of the scheduler's loop on a clock that only sleeping moves."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def test_the_loop_ticks_every_period_and_runs_the_slow_pass_every_slow_s(monkeypatch):
    fake, ticks = FakeTime(), []
    monkeypatch.setattr(scheduler, "time", fake)
    monkeypatch.setattr(scheduler, "tick", lambda clock, slow: ticks.append((fake.now, slow)) or {})
    monkeypatch.setattr(scheduler, "watch", lambda: {})
    scheduler.loop(scheduler.Clock(), period=0.5, should_stop=lambda: fake.now >= 1020.0, slow_every=5.0)
    assert len(ticks) == 40  # 20 s of ticks every half second
    slow = [round(at - 1000.0, 2) for at, was_slow in ticks if was_slow]
    assert slow == [0.0, 5.0, 10.0, 15.0]  # the first pass is slow, then one in every ten
