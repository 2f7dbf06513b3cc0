"""The forms people type (issue 17), each run through the real interpreter and executor in the simulator and
judged by what the simulated robot does: displacement, yaw change, dwell time, the places it visits."""

import math
import re
import threading
import time

import pytest

from execution.instructions import submit
from execution.models import Execution
from fleetcore.geometry import wrap
from robots.models import StateTransition
from tests.execution.helpers import at_rest, wait_final, wait_for

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow, pytest.mark.usefixtures("seeded_ontology")]

H, I_ = (0.0, 1.0), (-1.0, 1.0)  # two places of the paper world near the turtlebot's start (-2, -0.5)
NEAR = 0.25  # m: the robot is at a place


class Track:
    """Sample the simulated robot's pose (wall time, x, y, yaw) while an instruction runs."""

    def __init__(self, sim, name="turtlebot"):
        self.sim, self.body, self.samples = sim, sim.fleet.robots[name], []
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self.done.wait(0.03):
            self.samples.append((time.monotonic(), *self.sim.call(self.body.pose)))

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.done.set()
        self.thread.join(5)

    def visits(self, places: dict) -> list[str]:
        """The places reached, in order (one entry per arrival)."""
        out = []
        for _, x, y, _ in self.samples:
            at = next((name for name, p in places.items() if math.dist((x, y), p) < NEAR), None)
            if at and (not out or out[-1] != at):
                out.append(at)
        return out

    def dwell(self, place) -> float:
        """The longest stretch of time spent within NEAR of the place."""
        best, since = 0.0, None
        for t, x, y, _ in self.samples:
            if math.dist((x, y), place) < NEAR:
                since = t if since is None else since
                best = max(best, t - since)
            else:
                since = None
        return best

    def turned(self) -> float:
        """The signed yaw turned, in degrees, summed over the samples."""
        return math.degrees(
            sum(wrap(b[3] - a[3]) for a, b in zip(self.samples, self.samples[1:], strict=False))
        )


@pytest.fixture
def pose_store_of(turtle_world):
    """The turtlebot's simulated pose in the one store of last poses (what the links process keeps up)."""
    from robots.models import Robot
    from robots.poses import store_pose

    store_pose(Robot.objects.get(name="turtlebot").pk, pose(turtle_world))


def pose(sim, name="turtlebot"):
    return sim.call(sim.fleet.robots[name].pose)


def run(text, user, timeout=120):
    instruction = submit(text, user)
    assert instruction.status not in ("needs_user", "refused"), (text, instruction.outcome)
    instruction = wait_final(instruction, timeout=timeout)
    assert instruction.status == "succeeded", (text, instruction.status, instruction.outcome)
    return instruction


def test_move_forward_and_back_by_metres(turtle_world, fleet_admin):
    x0, y0, yaw0 = pose(turtle_world)
    run("move turtlebot 1 meter forward", fleet_admin)
    x1, y1, yaw1 = pose(turtle_world)
    ahead = (x1 - x0) * math.cos(yaw0) + (y1 - y0) * math.sin(yaw0)
    assert abs(ahead - 1.0) < 0.1 and math.dist((x0, y0), (x1, y1)) < 1.1
    assert abs(math.degrees(wrap(yaw1 - yaw0))) < 10  # straight, not turned round
    run("turtlebot, go back half a meter", fleet_admin)
    x2, y2, _ = pose(turtle_world)
    back = (x2 - x1) * math.cos(yaw1) + (y2 - y1) * math.sin(yaw1)
    assert abs(back + 0.5) < 0.1


def test_the_fleets_last_pose_of_a_robot_is_where_its_instruction_left_it(turtle_world, fleet_admin):
    """Where the portal places a robot once its instruction ended is where it came to rest, kept at the end
    (steps keep it only every half second while they run, and here no pose hub fills in)."""
    from robots.models import Robot
    from robots.poses import last_poses

    instruction = run("move turtlebot 1 meter forward", fleet_admin)
    robot = Robot.objects.get(name="turtlebot")
    kept, here = last_poses([robot.pk])[robot.pk], pose(turtle_world)
    ended = instruction.executions.get().finished_at.timestamp()
    assert kept["t"] >= ended - 0.25, (kept["t"], ended)  # kept as it ended, not during the drive
    assert math.dist((kept["x"], kept["y"]), here[:2]) < 0.01, (kept, here)


def said_degrees(instruction) -> float:
    """The signed degrees an instruction's outcome says the robot turned ("turned 104° left (90° left asked)")."""
    degrees, side = re.search(r"turned (\d+)° (left|right)", instruction.outcome).groups()
    return float(degrees) * (1 if side == "left" else -1)


def test_turn_left_then_right_by_degrees(turtle_world, fleet_admin):
    start = pose(turtle_world)
    with Track(turtle_world) as track:
        left = run("turn turtlebot left", fleet_admin)
    assert abs(track.turned() - 90) < 8
    assert abs(said_degrees(left) - track.turned()) < 4  # the words say what the robot did
    assert math.dist(start[:2], pose(turtle_world)[:2]) < 0.1  # on the spot
    with Track(turtle_world) as track:
        right = run("rotate turtlebot right by forty five degrees", fleet_admin)
    assert abs(track.turned() + 45) < 8
    assert abs(said_degrees(right) - track.turned()) < 4


def test_a_turn_that_runs_out_of_time_says_how_far_it_turned(turtle_world, fleet_admin, monkeypatch):
    """A relative motion that fails (out of time, or stuck) says how far the robot went, measured where it came
    to rest, as a finished one does: "did not finish within 1 s" alone left out what the robot had done."""
    from execution import handlers

    monkeypatch.setattr(handlers, "travel_time", lambda distance, turn, limits: 1.0)
    with Track(turtle_world) as track:
        instruction = wait_final(submit("turn turtlebot left 270 degrees", fleet_admin), timeout=60)
    assert instruction.status == "failed", instruction.outcome
    assert "did not finish within 1 s: turned" in instruction.outcome, instruction.outcome
    assert 20 < track.turned() < 250
    assert abs(said_degrees(instruction) - track.turned()) < 4, (instruction.outcome, track.turned())


def test_a_robots_start_is_three_calls_through_the_blocking_pool_before_its_first_command(
    turtle_world, fleet_admin, monkeypatch
):
    """Every call through the executor's blocking pool waits behind every other robot's: 50 robots started at
    once took 2 to 5 s to their first command with six calls each (bench.cluster, "under instructions"). The lock
    is taken on the loop; the claim and the link's bindings are one call."""
    from execution import blocking

    calls, real = [], blocking.call

    async def counted(fn, /, *args, **kwargs):
        calls.append(getattr(fn, "__name__", repr(fn)))
        return await real(fn, *args, **kwargs)

    monkeypatch.setattr(blocking, "call", counted)
    with Track(turtle_world) as track:
        run("turn turtlebot left by 45 degrees", fleet_admin)
    assert abs(track.turned() - 45) < 8  # it did start, and turn
    assert calls.index("_stamp") == 3  # the first command's time is kept once it is sent
    assert calls[:3] == ["next_execution", "_begin", "transition"]


def test_go_wait_then_go_dwells_and_visits_in_order(turtle_world, fleet_admin):
    with Track(turtle_world) as track:
        run("move turtlebot to I, wait 3 seconds, then go to H", fleet_admin)
    assert track.visits({"I": I_, "H": H})[-2:] == ["I", "H"]
    assert track.dwell(I_) >= 3.0  # wall-clock seconds: the wait is in real time
    assert math.dist(pose(turtle_world)[:2], H) < 0.15


def test_patrol_twice_visits_each_place_twice_in_turn(turtle_world, fleet_admin):
    with Track(turtle_world) as track:
        run("patrol between I and H twice with turtlebot", fleet_admin)
    assert track.visits({"I": I_, "H": H}) == ["I", "H", "I", "H"]


def test_patrol_until_stopped_goes_round_until_a_stop(turtle_world, fleet_admin):
    with Track(turtle_world) as track:
        instruction = submit("turtlebot patrol H and I until stopped", fleet_admin)
        wait_for(
            lambda: track.visits({"I": I_, "H": H})[:4] == ["H", "I", "H", "I"], timeout=120, what="2 rounds"
        )
        instruction.refresh_from_db()
        assert instruction.status == "running"  # still going round
        stop = submit("stop turtlebot", fleet_admin)
    assert stop.status == "succeeded", stop.outcome
    assert wait_final(instruction).status == "cancelled"
    assert wait_for(lambda: at_rest(turtle_world, "turtlebot"), timeout=5, what="at rest")


def test_come_back_to_your_start(turtle_world, fleet_admin):
    start = pose(turtle_world)
    run("move turtlebot to H", fleet_admin)
    assert math.dist(pose(turtle_world)[:2], start[:2]) > 1.0
    run("turtlebot, come back to your start", fleet_admin)
    assert math.dist(pose(turtle_world)[:2], start[:2]) < 0.2


def test_move_and_do_not_clean_moves_without_cleaning(turtle_world, fleet_admin):
    instruction = run("move turtlebot to H and do not clean", fleet_admin)
    assert math.dist(pose(turtle_world)[:2], H) < 0.15
    reasons = StateTransition.objects.filter(instruction=instruction).values_list("reason", flat=True)
    assert reasons and not any("clean" in reason for reason in reasons)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("where is turtlebot", "turtlebot is at (-2.0"),
        ("what is turtlebot doing", "turtlebot is doing nothing"),
        ("which robots are free", "Free: turtlebot"),
        ("how far is turtlebot from H", "turtlebot is 2.5 m from H in a straight line"),
        ("what can turtlebot do", "turtlebot can move, navigate"),
        ("don't move turtlebot", "Nothing to do: not move turtlebot"),
    ],
)
def test_questions_and_a_negation_answer_without_moving_anything(
    turtle_world, fleet_admin, pose_store_of, text, words
):
    before = pose(turtle_world)
    instruction = submit(text, fleet_admin)
    assert instruction.status == "succeeded" and words in instruction.outcome, instruction.outcome
    assert not Execution.objects.exists()  # nothing queued, nothing ran
    time.sleep(0.3)
    assert math.dist(before[:2], pose(turtle_world)[:2]) < 0.01


def test_a_question_is_answered_while_the_robot_is_busy(turtle_world, fleet_admin, pose_store_of):
    moving = submit("move turtlebot to B", fleet_admin)
    wait_for(lambda: Execution.objects.filter(status="running").exists(), what="the move running")
    answer = submit("what is turtlebot doing", fleet_admin)
    assert answer.status == "succeeded"
    assert f"instruction #{moving.pk} 'move turtlebot to B', step 1 of 1 (move to B)" in answer.outcome
    assert wait_final(moving, timeout=120).status == "succeeded"
