"""A stop holds (access.holds): a robot a person stopped is moved by nothing automatic (make-way, "any" and
"all robots", a schedule's slot, work queued before the stop) until a person releases it or names it.

Robots are rows here (no simulator): what is judged is what dispatch, the scheduler, traffic and the runner
decide. tests/execution/test_hold_sim.py judges the same on simulated robots, by their odometry."""

import datetime
import time

import pytest
from django.utils import timezone

from access import holds, leases
from audit.models import AuditEntry
from execution import (
    control,
    coordination,
    dispatch,
    runner,
    scheduler,
    traffic,
    traffic_fleet,
    traffic_state,
)
from execution.instructions import submit
from execution.models import Execution, Instruction, TimeSlot
from places.models import Location
from places.worlds import load_world_into_db
from robots.models import Binding, Robot
from robots.poses import forget_poses, store_poses
from tests.execution.helpers import parse, step

SQUARE = [[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]]
D = (5.0, 5.0)


@pytest.fixture
def fleet(db, exec_settings, monkeypatch):
    """The paper map; a helper adding an online, ready robot with a pose; nothing starts running."""
    load_world_into_db("paper")
    monkeypatch.setattr(dispatch.executor, "wake", lambda robot_ids: None)
    made = []

    def add(name, x, y):
        robot = Robot.objects.create(
            name=name, endpoint=f"ws://sim/{name}", footprint=SQUARE, link_status="online", state="ready"
        )
        for role in ("move", "odometry"):
            Binding.objects.create(robot=robot, action=role, target=f"/{name}/{role}")
        store_poses([{"id": robot.pk, "x": x, "y": y, "yaw": 0.0}])
        made.append(robot)
        return robot

    yield add
    forget_poses([robot.pk for robot in made])


def held_words(robot) -> str:
    return Robot.objects.select_related("held_by").get(pk=robot.pk).hold_words


def test_a_persons_stop_holds_the_robot_and_the_systems_stop_does_not(fleet, fleet_admin, monkeypatch):
    monkeypatch.setattr(
        control, "_publish_zero", lambda robot, surface: "stopped"
    )  # no simulator: the zero is elsewhere
    tiago, husky = fleet("tiago", 0.0, -3.0), fleet("husky", 1.5, -1.3)
    control.stop([tiago], fleet_admin)
    control.stop([husky], None)  # the system's (a task, the watchdog): nothing to hold for a person
    at = timezone.localtime(Robot.objects.get(pk=tiago.pk).held_at)
    assert held_words(tiago) == f"held by a stop (ada, {at:%H:%M:%S})"
    assert held_words(husky) is None


def test_any_robot_passes_over_a_held_robot_and_says_why(fleet, fleet_admin):
    near, far = fleet("near", 4.0, 4.5), fleet("far", -4.0, -4.0)
    holds.hold([near], fleet_admin)
    robot, why = dispatch.allocate(dispatch.Step.from_dict(step("any", *D, "D")), fleet_admin)
    assert robot == far
    assert f"near is {held_words(near)}" in why
    holds.hold([far], fleet_admin)  # nobody free: the instruction waits, saying why
    waiting = submit("go to D", fleet_admin, parse=parse(step("any", *D, "D")))
    assert waiting.status == "queued" and not waiting.executions.exists()
    assert f"far is {held_words(far)}" in waiting.outcome and f"near is {held_words(near)}" in waiting.outcome


def test_all_robots_leave_a_held_robot_out_and_say_so(fleet, fleet_admin):
    held, free = fleet("tiago", 0.0, -3.0), fleet("husky", 1.5, -1.3)
    holds.hold([held], fleet_admin)
    instruction = submit("all robots to D", fleet_admin, parse=parse(step("all", *D, "D")))
    assert list(instruction.robots.all()) == [free]
    assert f"left out: tiago is {held_words(held)}" in instruction.outcome


@pytest.mark.django_db(transaction=True)  # the scheduler's tick closes old connections
def test_a_schedule_slot_does_not_start_on_a_held_robot(fleet, fleet_admin):
    tiago = fleet("tiago", 0.0, -3.0)
    goal = Location.objects.get(name="G")
    TimeSlot.objects.create(robot=tiago, start=datetime.time(0, 0), end=datetime.time(23, 59, 59), goal=goal)
    holds.hold([tiago], fleet_admin)
    (instruction,) = scheduler.run_due_slots(timezone.now())
    assert instruction.user is None and instruction.source == "schedule"
    assert instruction.status == "refused" and not instruction.executions.exists()
    assert instruction.outcome.startswith(f"tiago is {held_words(tiago)}: nothing automatic moves it")
    assert 'type "release tiago"' in instruction.outcome


def test_a_persons_instruction_naming_a_held_robot_releases_it_and_says_so(fleet, fleet_admin):
    tiago = fleet("tiago", 0.0, -3.0)
    holds.hold([tiago], fleet_admin)
    words = held_words(tiago)
    instruction = submit("move tiago to D", fleet_admin, parse=parse(step(["tiago"], *D, "D")))
    assert instruction.status == "queued" and instruction.executions.get().robot == tiago
    assert f"tiago released from its hold ({words})" in instruction.outcome
    assert held_words(tiago) is None
    assert AuditEntry.objects.filter(action="hold.release", target="tiago").exists()


def test_release_typed_lets_the_robot_go_and_a_viewer_may_not(fleet, fleet_admin, viewer):
    tiago, husky = fleet("tiago", 0.0, -3.0), fleet("husky", 1.5, -1.3)
    holds.hold([tiago, husky], fleet_admin)
    release = {"action": "release", "robots": ["tiago"], "destination": None}
    refused = submit("release tiago", viewer, parse=parse(release))
    assert refused.status == "refused" and held_words(tiago) is not None
    words = held_words(tiago)
    done = submit("release tiago", fleet_admin, parse=parse(release))
    assert done.status == "succeeded" and done.outcome == f"released tiago ({words})"
    assert held_words(tiago) is None and held_words(husky) is not None
    again = submit("release tiago", fleet_admin, parse=parse(release))
    assert again.outcome == "tiago was not held"
    every = submit("release", fleet_admin, parse=parse({**release, "robots": "all"}))
    assert every.outcome.startswith("released husky") and held_words(husky) is None


def test_work_queued_before_the_stop_does_not_start_on_the_held_robot(fleet, fleet_admin):
    """A race with the stop's cancel of queued work: the runner cancels it, with the hold's words."""
    tiago = fleet("tiago", 0.0, -3.0)
    queued = submit("move tiago to D", fleet_admin, parse=parse(step(["tiago"], *D, "D")))
    holds.hold([tiago], fleet_admin)
    execution = queued.executions.get()
    assert runner._held_back(execution)
    execution.refresh_from_db()
    assert execution.status == "cancelled" and execution.error.startswith(f"tiago is {held_words(tiago)}")
    assert Instruction.objects.get(pk=queued.pk).status == "cancelled"


def make_way_asked(redis, asker, asked) -> None:
    """What asker's plan writes when it asks `asked` to make way (traffic_state.request_way)."""
    entry = {"for": asker.pk, "r": 0.3, "route": [[-4.0, -2.0], [4.0, -2.0]], "sent": False}
    traffic_state.write(redis, "makeway", asked.pk, {**entry, "expires": time.time() + 60})


def test_make_way_is_the_systems_with_its_cause_and_never_moves_a_held_or_leased_robot(
    fleet, fleet_admin, operator
):
    a, b, c = fleet("a", -2.0, 0.0), fleet("b", 0.0, -2.0), fleet("c", 2.0, -2.0)
    redis = coordination.connection()
    running = submit("move a to D", fleet_admin, parse=parse(step(["a"], *D, "D")))
    Execution.objects.filter(instruction=running).update(status="running")
    _, still = traffic.obstacles(redis, a.pk, time.time())
    through = [(-4.0, -2.0), (4.0, -2.0)]  # b and c stand on it
    assert set(traffic._idle_in_the_way(redis, a, through, still)) == {b.pk, c.pk}
    holds.hold([b], fleet_admin)
    leases.take(operator, c)
    assert traffic._idle_in_the_way(redis, a, through, still) == {}  # neither is asked
    assert "b, held by a stop (ada" in traffic_fleet.held_in_the_way(a, (-4.0, -2.0), (4.0, -2.0))
    make_way_asked(redis, a, b)  # asked all the same (as before the stop): refused, in words
    make_way_asked(redis, a, c)
    traffic.ask_to_make_way(a)
    table = traffic_state.read(redis, "makeway")  # the refusal answered through the signal, kept in the table
    for robot, said in ((b, f"b is {held_words(b)}"), (c, "c is held by otto (control lease)")):
        made = Instruction.objects.get(text=f"{robot.name} make way for a")
        assert made.status == "refused" and made.outcome.startswith(said), made.outcome
        assert table[robot.pk]["sent"] and table[robot.pk]["refused"] == made.outcome
    holds.release([b], fleet_admin)
    leases.release(operator, c)
    make_way_asked(redis, a, b)
    traffic.ask_to_make_way(a)
    made = Instruction.objects.filter(text="b make way for a").latest("pk")
    assert made.status == "queued" and made.executions.get().robot == b
    assert traffic_state.read(redis, "makeway")[b.pk]["refused"] == ""  # taken: its step may read the request
    assert (made.user, made.source) == (None, "traffic")  # the system's, never a person's
    assert made.cause == f"make way for a, instruction #{running.pk} by ada"


def test_a_stops_status_pushes_go_in_one_hand_over_in_order(
    transactional_db, exec_settings, fleet_admin, monkeypatch
):
    """control.stop holds the robots and pushes each one's status: from a thread with no loop of its own that was a
    new event loop, thread and Redis connection per robot (0.8 s of CPU for 100 robots). Now one hand-over for
    the stop's pushes (live.together), each robot's status in it, in the robots' order."""
    import live

    monkeypatch.setattr(control, "_publish_zero", lambda robot, surface: "stopped")  # no simulator here
    robots = [
        Robot.objects.create(name=f"r{n}", endpoint=f"ws://sim/r{n}", footprint=SQUARE) for n in range(4)
    ]
    handed, pushed = [], []
    monkeypatch.setattr(live, "_send_all", lambda pushes: handed.append(pushes))
    monkeypatch.setattr(live, "async_to_sync", lambda fn: pushed.append(fn) or (lambda *a, **k: None))
    control.stop(robots, fleet_admin)
    statuses = [
        p["robot"] for group, p in handed[0] if group == live.FLEET_GROUP and p["type"] == "robot.status"
    ]
    assert len(handed) == 1 and statuses == [r.name for r in robots] and pushed == []
