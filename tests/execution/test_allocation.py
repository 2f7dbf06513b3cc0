"""Allocation: an instruction that names no robot goes to the one best robot (or the selected ones), and waits
when nobody is free; goals taken by another robot become the nearest free spot, and the person is told."""

import math

import pytest

from execution import dispatch, scheduler
from execution.instructions import submit
from execution.models import Execution, Instruction
from fleetcore.traffic import SPOT_MARGIN
from places.worlds import load_world_into_db
from robots.models import Binding, Robot
from robots.poses import forget_poses, store_poses
from tests.execution.helpers import parse, step

SQUARE = [[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]]
HUSKY = [[-0.5, -0.34], [-0.5, 0.34], [0.5, 0.34], [0.5, -0.34]]
D = (5.0, 5.0)  # inside Room 1 of the paper world: its door faces west, its south wall (y = 3) is solid


@pytest.fixture
def fleet(db):
    """The paper world's map in the database, and a helper that adds a ready robot with a pose."""
    load_world_into_db("paper")
    made = []

    def add(name, x, y, footprint=SQUARE, roles=("move", "odometry"), state="ready"):
        robot = Robot.objects.create(
            name=name, endpoint=f"ws://sim/{name}", footprint=footprint, link_status="online", state=state
        )
        for role in roles:
            Binding.objects.create(robot=robot, action=role, target=f"/{name}/{role}")
        store_poses([{"id": robot.pk, "x": x, "y": y, "yaw": 0.0}])
        made.append(robot)
        return robot

    yield add
    forget_poses([robot.pk for robot in made])


@pytest.fixture
def no_runner(exec_settings, monkeypatch):
    """Instructions are stored and dispatched; nothing starts running them."""
    monkeypatch.setattr(dispatch.executor, "wake", lambda robot_ids: None)


def to(x, y, name="P", task=None, action="move"):
    return step("any", x, y, name, task=task, action=action)


def test_the_shortest_planned_path_wins_not_the_straight_line(fleet, fleet_admin):
    behind_wall = fleet("south", 4.5, 2.4)  # 2.6 m from D as the crow flies, ~5 m round by the door
    fleet("west", 1.0, 4.6)  # 4.0 m from D, and the path is about as long
    robot, why = dispatch.allocate(dispatch.Step.from_dict(to(*D, "D")), fleet_admin)
    assert robot.name == "west"
    assert why.startswith("west chosen (no robot named): the nearest free robot, 4.") and "south" in why
    assert math.dist((4.5, 2.4), D) < 3.0 and behind_wall.name in why


def test_busy_held_and_unbound_robots_are_passed_over_with_the_reason(fleet, fleet_admin):
    fleet("near", 4.0, 4.5, state="motion")
    fleet("blind", 4.2, 4.6, roles=("move",))
    fleet("far", -4.0, -4.0)
    robot, why = dispatch.allocate(dispatch.Step.from_dict(to(*D, "D")), fleet_admin)
    assert robot.name == "far"
    assert "near is busy (motion)" in why and "blind has no odometry or pose bound" in why


def test_a_robot_named_for_an_action_it_has_no_binding_for_is_refused_at_once_saying_what_it_lacks(
    fleet, fleet_admin, no_runner
):
    """Not queued to fail when it runs: the same words allocation gives a robot it passes over."""
    fleet("tb", -2.0, 2.0)
    photo = {"action": "photograph", "robots": ["tb"], "destination": None, "task": "photograph"}
    refused = submit("tb, take a photo", fleet_admin, parse=parse(photo))
    assert refused.status == "refused" and not Execution.objects.filter(instruction=refused).exists()
    assert (
        refused.outcome
        == "tb cannot photograph: it has no camera bound; choose one on its registration page."
    )
    fleet("blind", 4.2, 4.6, roles=("move",))
    refused = submit("move blind to D", fleet_admin, parse=parse(step(["blind"], *D, "D")))
    assert (
        refused.status == "refused"
        and "blind cannot move: it has no odometry or pose bound" in refused.outcome
    )


def test_ties_go_to_the_fuller_battery(fleet, fleet_admin):
    low = fleet("low", 0.0, -1.0)
    high = fleet("high", 0.0, 1.0)
    low.description, high.description = {"battery": 20}, {"battery": 90}
    low.save(), high.save()
    robot, why = dispatch.allocate(dispatch.Step.from_dict(to(-1.0, 0.0, "Q")), fleet_admin)
    assert robot.name == "high" and "battery 90%" in why


def test_an_instruction_naming_no_robot_moves_one_and_says_which_and_why(fleet, fleet_admin, no_runner):
    fleet("a", -4.0, -4.0)
    fleet("b", 1.0, 4.6)
    instruction = submit("go to D", fleet_admin, parse=parse(to(*D, "D")))
    robots = list(Execution.objects.filter(instruction=instruction).values_list("robot__name", flat=True))
    assert robots == ["b"]
    assert instruction.status == "queued" and instruction.outcome.startswith(
        "b chosen (no robot named): the nearest free robot, "
    )


@pytest.mark.usefixtures("seeded_ontology")
def test_every_form_naming_no_robot_says_whom_it_chose_and_why(fleet, fleet_admin, no_runner):
    """go home, a patrol, a task, and a stop (which stops them all), typed without a robot's name."""
    fleet("a", -4.0, -4.0)
    fleet("b", 1.0, 4.6)
    for text, why in [
        ("go home", "the first by name of the 2 free robots that can do it"),
        ("patrol between A and B twice", "the nearest free robot, 2.8 m to A (a 8.5+ m)"),
        ("spin around", "the first by name of the 2 free robots that can do it"),
    ]:
        instruction = submit(text, fleet_admin)
        chosen = Execution.objects.get(instruction=instruction).robot.name
        assert instruction.outcome.startswith(f"{chosen} chosen (no robot named): {why}"), instruction.outcome
        Execution.objects.update(status="cancelled")  # (nothing runs them: both are free again)
    stop = submit("stop", fleet_admin)
    assert stop.outcome.startswith("every robot stopped (2: a stop that names no robot stops them all). a:")
    assert set(stop.robots.values_list("name", flat=True)) == {"a", "b"}


def test_the_robots_selected_on_the_page_take_an_instruction_naming_none(fleet, fleet_admin, no_runner):
    fleet("a", -4.0, -4.0)
    near = fleet("b", 1.0, 4.6)
    far = fleet("c", -4.0, 4.0)
    instruction = submit("go to D", fleet_admin, parse=parse(to(*D, "D")), robot_ids=[far.pk])
    assert list(instruction.robots.values_list("name", flat=True)) == ["c"]
    assert instruction.outcome.startswith("c chosen (no robot named): selected on the page")
    named = submit("move b to D", fleet_admin, parse=parse(step(["b"], *D, "D")), robot_ids=[far.pk])
    assert list(named.robots.values_list("pk", flat=True)) == [near.pk]  # the text's name wins


@pytest.mark.usefixtures("seeded_ontology")
def test_the_parse_line_of_an_instruction_to_selected_robots_names_them(fleet, fleet_admin, no_runner):
    """The console's parse line said "a robot the portal chooses" for the robots the person had selected: the
    interpreter reads the text before the selection is applied. Stored, it says them; a name in the text stays."""
    a, c = fleet("a", -4.0, -4.0), fleet("c", -4.0, 4.0)
    fleet("b", 1.0, 4.6)
    instruction = submit("turn left 90 degrees", fleet_admin, robot_ids=[c.pk, a.pk])
    assert sorted(instruction.robots.values_list("name", flat=True)) == ["a", "c"]
    stored = Instruction.objects.get(pk=instruction.pk)
    assert instruction.parse == stored.parse
    [line] = stored.parse["read_back"]
    assert "chooses" not in line and line.startswith("turn_by c") and " a " in f"{line} ", line
    named = submit("turn b left 90 degrees", fleet_admin, robot_ids=[c.pk])
    assert Instruction.objects.get(pk=named.pk).parse["read_back"] == named.parse["read_back"]
    assert named.parse["read_back"][0].startswith("turn_by b"), named.parse


@pytest.mark.django_db(transaction=True)  # the scheduler's tick closes old connections
def test_nobody_free_the_instruction_waits_and_is_allocated_when_one_is(fleet, fleet_admin, no_runner):
    busy = fleet("busy", 1.0, 4.6, state="motion")
    instruction = submit("go to D", fleet_admin, parse=parse(to(*D, "D")))
    assert instruction.status == "queued" and not instruction.executions.exists()
    assert (
        instruction.outcome.startswith("waiting for a free robot")
        and "busy is busy (motion)" in instruction.outcome
    )
    assert dispatch.retry() == []  # still busy: still waiting
    Robot.objects.filter(pk=busy.pk).update(state="ready")
    report = scheduler.tick(scheduler.Clock())
    assert report["allocated"] == [instruction.pk]
    instruction.refresh_from_db()
    assert list(instruction.robots.values_list("name", flat=True)) == ["busy"]
    assert instruction.outcome.startswith("busy chosen (no robot named): the nearest free robot")


def test_no_capable_robot_is_a_refusal_not_a_wait(fleet, fleet_admin):
    fleet("blind", 1.0, 4.6, roles=("move",))
    instruction = submit("go to D", fleet_admin, parse=parse(to(*D, "D")))
    assert instruction.status == "refused" and "blind has no odometry or pose bound" in instruction.outcome


def test_a_waiting_instruction_is_refused_after_the_limit(fleet, fleet_admin, no_runner):
    import datetime

    fleet("busy", 1.0, 4.6, state="motion")
    instruction = submit("go to D", fleet_admin, parse=parse(to(*D, "D")))
    later = instruction.received_at + datetime.timedelta(seconds=dispatch.WAIT_LIMIT_S + 1)
    dispatch.retry(later)
    instruction.refresh_from_db()
    assert instruction.status == "refused" and "no robot became free within 10 min" in instruction.outcome


def test_a_goal_where_a_robot_is_parked_becomes_the_nearest_free_spot(fleet, fleet_admin, no_runner):
    parked = fleet("parked", 2.0, 2.0, footprint=HUSKY)  # on A
    fleet("tb", -2.0, 2.0)
    instruction = submit("move tb to A", fleet_admin, parse=parse(step(["tb"], 2.0, 2.0, "A")))
    goal = Execution.objects.get(instruction=instruction).steps[0]["destination"]
    gap = math.dist((goal["x"], goal["y"]), (2.0, 2.0))
    assert gap >= dispatch.spots.radius_of(parked) + 0.14 + SPOT_MARGIN - 1e-6  # clear of the Husky's corners
    assert gap < 1.2 and goal["around"] == "A"
    assert goal["x"] < 2.0  # on tb's side (it comes from the west)
    assert "A is taken by parked: tb goes to a free spot" in instruction.outcome
    assert f"{gap:.1f} m" in instruction.outcome and "west of A" in instruction.outcome


def test_a_robot_whose_pose_was_never_kept_is_given_a_spot_on_the_side_it_starts_from(
    fleet, fleet_admin, no_runner
):
    """Where no pose hub runs (or before its first tick) a robot that has not moved since registration has no
    last pose: it stands where it started, and the spot it gets by a taken place is on that side. (Without a
    place, the first free spot round the place, east of it, went to a TurtleBot coming from the west, beyond
    the robot that held the doorway: it could never get there.)"""
    fleet("parked", 3.0, 4.6, footprint=HUSKY)  # in Room 1's doorway (its door faces west)
    tb = fleet("tb", -2.0, -0.5)
    forget_poses([tb.pk])
    Robot.objects.filter(pk=tb.pk).update(start_pose=[-2.0, -0.5, 0.0])
    instruction = submit("move tb to parked", fleet_admin, parse=parse(step(["tb"], 3.0, 4.6, "parked")))
    goal = Execution.objects.get(instruction=instruction).steps[0]["destination"]
    assert goal["x"] < 3.0, goal  # outside the room, on tb's side of the doorway
    assert "west of parked" in instruction.outcome, instruction.outcome


def test_two_instructions_to_one_place_never_share_the_spot(fleet, fleet_admin, no_runner):
    """The reported bug: "move tb3_1 to A" then "move tb3_2 to A" ended on one spot."""
    fleet("tb3_1", -2.0, 2.0)
    fleet("tb3_2", -2.0, -2.0)
    first = submit("move tb3_1 to A", fleet_admin, parse=parse(step(["tb3_1"], 2.0, 2.0, "A")))
    second = submit("move tb3_2 to A", fleet_admin, parse=parse(step(["tb3_2"], 2.0, 2.0, "A")))
    a = Execution.objects.get(instruction=first).steps[0]["destination"]
    b = Execution.objects.get(instruction=second).steps[0]["destination"]
    assert (a["x"], a["y"]) == (2.0, 2.0)
    assert math.dist((a["x"], a["y"]), (b["x"], b["y"])) >= 2 * math.hypot(0.1, 0.1) + SPOT_MARGIN - 1e-6
    assert "A is taken by tb3_1's goal" in second.outcome
    assert Instruction.objects.get(pk=first.pk).outcome == ""  # nothing to tell: A was free


def test_the_api_takes_the_robots_selected_on_the_page(
    fleet, fleet_admin, client_for, no_runner, monkeypatch
):
    from execution import instructions

    monkeypatch.setattr(instructions, "_interpret", lambda text: parse(to(*D, "D")))
    fleet("near", 1.0, 4.6)
    far = fleet("far", -4.0, 4.0)
    client = client_for(fleet_admin)
    response = client.post(
        "/api/instructions", {"text": "go to D", "robot_ids": [far.pk]}, content_type="application/json"
    )
    assert response.status_code == 201, response.content
    assert list(Instruction.objects.get(pk=response.json()["id"]).robots.values_list("name", flat=True)) == [
        "far"
    ]
    bad = client.post(
        "/api/instructions", {"text": "go to D", "robot_ids": "far"}, content_type="application/json"
    )
    assert bad.status_code == 422 and "robot_ids" in bad.content.decode()


def three_in_the_warehouse(fleet, settings):
    """husky1, husky2 (the simulated Husky's footprint) and tb05 at their start poses in the warehouse world."""
    load_world_into_db("warehouse")
    settings.FLEET_WORLD = "warehouse"
    husky = [[-0.495, -0.285], [-0.495, 0.285], [0.495, 0.285], [0.495, -0.285]]
    robots = [fleet("husky1", 1.2, 5.0, footprint=husky), fleet("husky2", 1.2, 6.5, footprint=husky)]
    return [*robots, fleet("tb05", 5.5, 1.0)]


def test_spots_found_for_robots_when_the_place_is_taken_have_room_for_them_to_turn(
    fleet, fleet_admin, no_runner, settings
):
    """Tried as a user: "move husky1, husky2 and tb05 to Cross" sent husky2 to a spot 1.4 m north of Cross,
    0.64 m from a rack's corner, where it could stand but not turn, and it stalled turning into it."""
    robots = three_in_the_warehouse(fleet, settings)
    names = [robot.name for robot in robots]
    instruction = submit(
        "move husky1, husky2 and tb05 to Cross", fleet_admin, parse=parse(step(names, 15.0, 12.0, "Cross"))
    )
    assert "goes to a free spot" in instruction.outcome  # (the ring round Cross has no room for all three)
    for execution in Execution.objects.filter(instruction=instruction):
        goal = execution.steps[0]["destination"]
        turning = dispatch.spots.route.planner_for(execution.robot, turning=True)
        assert turning.free(*turning.to_cell(goal["x"], goal["y"])), (execution.robot.name, goal)


def test_robots_sent_again_to_the_place_they_stand_round_stay_where_they_stand(
    fleet, fleet_admin, no_runner, settings
):
    """Tried as a user: "move husky1, husky2 and tb05 to Cross" said a second time, once all three stood round
    Cross, sent husky2, parked by a rack, to another spot a metre off, and it stalled turning by the rack three
    times. A robot standing free by the place, no farther from it than its spot, stays; a robot elsewhere
    still goes to the place."""
    robots = three_in_the_warehouse(fleet, settings)
    names = [robot.name for robot in robots]
    text, parsed = "move husky1, husky2 and tb05 to Cross", parse(step(names, 15.0, 12.0, "Cross"))
    first = submit(text, fleet_admin, parse=parsed)
    goals = {}
    for execution in Execution.objects.filter(instruction=first):  # each arrives at its goal
        goal = execution.steps[0]["destination"]
        goals[execution.robot.name] = (goal["x"], goal["y"])
        store_poses([{"id": execution.robot.pk, "x": goal["x"], "y": goal["y"], "yaw": 0.0}])
    Execution.objects.filter(instruction=first).update(status="succeeded")
    again = submit(text, fleet_admin, parse=parsed)
    for execution in Execution.objects.filter(instruction=again):
        goal = execution.steps[0]["destination"]
        assert math.dist((goal["x"], goal["y"]), goals[execution.robot.name]) < 1e-3, execution.robot.name
    assert "goes to a free spot" not in again.outcome and "stays where it stands" in again.outcome
    store_poses([{"id": robots[2].pk, "x": 5.5, "y": 1.0, "yaw": 0.0}])
    Execution.objects.filter(instruction=again).update(status="succeeded")
    alone = submit("move tb05 to Cross", fleet_admin, parse=parse(step(["tb05"], 15.0, 12.0, "Cross")))
    goal = Execution.objects.get(instruction=alone).steps[0]["destination"]
    assert math.dist((goal["x"], goal["y"]), (5.5, 1.0)) > 5.0  # from afar it goes, as before


def test_spots_given_one_by_one_never_wall_off_a_goal_given_before(fleet, fleet_admin, no_runner):
    """Tried as an operator: four robots sent to A one by one; husky, given A, never got in past the spots given
    after it to the others (it failed after 139 s). Here a Husky is given A and eight small robots come after it
    from all sides: each is given a spot it can get to, and the Husky can still get to A past all of them."""
    husky = fleet("husky", -1.0, 2.0, footprint=HUSKY)
    first = submit("move husky to A", fleet_admin, parse=parse(step(["husky"], 2.0, 2.0, "A")))
    assert first.executions.get().steps[0]["destination"]["x"] == 2.0  # it has A itself
    starts = [
        (-1.0, 4.0),
        (0.0, 0.0),
        (4.0, 1.0),
        (4.0, 2.5),
        (-1.0, 0.5),
        (0.5, 5.0),
        (2.0, 5.0),
        (5.0, 1.5),
    ]
    robots = [fleet(f"t{i}", x, y) for i, (x, y) in enumerate(starts)]
    goals = []
    for robot in robots:
        sent = submit(f"move {robot.name} to A", fleet_admin, parse=parse(step([robot.name], 2.0, 2.0, "A")))
        assert sent.status == "queued", sent.outcome
        goal = sent.executions.get().steps[0]["destination"]
        goals.append((goal["x"], goal["y"], dispatch.spots.radius_of(robot)))
        planner = dispatch.spots.route.planner_for(robot)
        others = [g for g in goals[:-1]] + [(2.0, 2.0, dispatch.spots.radius_of(husky))]
        assert planner.plan(starts[len(goals) - 1], goals[-1][:2], avoid=others), (
            robot.name
        )  # it can get there
    planner = dispatch.spots.route.planner_for(husky)
    assert planner.plan((-1.0, 2.0), (2.0, 2.0), avoid=goals) is not None  # and so can the Husky to A
