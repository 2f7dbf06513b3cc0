"""Navigation stacks through their actions, and speed words kept on every kind of robot.

nav2 (tb3_nav2) navigates through navigate_to_pose; a stop cancels its goal at the action server (the
simulator records each cancel) and the robot comes to rest. "slowly" reaches every robot: nav2 as a SpeedLimit,
move_base (husky, tiago) as its local planner's max_vel_x, a robot without a stack (spot) as the portal's own
speed. Judged by the simulated robots: the action server's records and the peak speed odometry reports."""

import math
import threading

import pytest

from execution.instructions import submit
from execution.models import Instruction
from fleetcore import speed
from robots.models import Robot
from robots.rosbridge import sync
from simworker.testing import running_world, send_home
from tests.execution.conftest import register
from tests.execution.helpers import at_rest, wait_final, wait_for

pytestmark = [pytest.mark.timeout(240), pytest.mark.slow, pytest.mark.usefixtures("seeded_ontology")]


@pytest.fixture
def nav_world(request, executor):
    """The paper world with the endpoints named by the test's parameter registered, at three times real time."""
    keys = request.param
    with running_world("paper", endpoints=keys, time_scale=3.0) as sim:
        sim.robots = register(sim, keys)
        yield sim


class PeakSpeed:
    """The highest forward speed the robot's own odometry reports while watched (a simulated value, no timing)."""

    def __init__(self, robot: Robot) -> None:
        odometry = robot.bindings.get(action="odometry")
        self.client = sync.get_client(robot.endpoint)
        self.lock, self.peak = threading.Lock(), 0.0
        self.sub = self.client.subscribe(odometry.target, odometry.message_type, self._on)

    def _on(self, msg: dict) -> None:
        with self.lock:
            self.peak = max(self.peak, abs(msg["twist"]["twist"]["linear"]["x"]))

    def close(self) -> float:
        self.client.unsubscribe(self.sub)
        return self.peak


def trips(sim, user, texts: dict[str, str]) -> dict[str, tuple[Instruction, float]]:
    """Run one instruction per robot at once, each from its start pose; return each with the robot's peak speed."""
    sim.call(send_home, sim.fleet, list(texts))
    watches = {name: PeakSpeed(Robot.objects.get(name=name)) for name in texts}
    try:
        sent = {name: submit(text, user) for name, text in texts.items()}
        done = {name: wait_final(instruction, timeout=200) for name, instruction in sent.items()}
    finally:
        peaks = {name: watch.close() for name, watch in watches.items()}
    return {name: (done[name], peaks[name]) for name in texts}


@pytest.mark.parametrize("nav_world", [["tb3_nav2"]], indirect=True)
def test_nav2_navigates_through_its_action_and_a_stop_cancels_the_goal(nav_world, fleet_admin):
    stack = nav_world.fleet.robots["tb3_nav2"].navigator
    instruction = wait_final(submit("navigate tb3_nav2 to C", fleet_admin), timeout=200)
    assert instruction.status == "succeeded", instruction.outcome
    x, y, _ = nav_world.call(nav_world.fleet.robots["tb3_nav2"].pose)
    assert math.dist((x, y), (2.0, -2.0)) < 0.35
    goals = nav_world.call(lambda: list(stack.statuses["/navigate_to_pose"]))
    assert goals and all(g.handle is not None for g in goals)  # action goals from the portal, not /goal_pose
    assert goals[-1].status == 4  # SUCCEEDED

    running = submit("move tb3_nav2 to B", fleet_admin)
    body = nav_world.fleet.robots["tb3_nav2"].body
    wait_for(lambda: nav_world.call(lambda: abs(body.vx) > 0.05), timeout=60, what="tb3_nav2 moving")
    submit("stop tb3_nav2", fleet_admin)
    cancelled = lambda: ("/navigate_to_pose", "service") in nav_world.call(lambda: list(stack.cancels))  # noqa: E731
    # the stop's cancel_goal call leaves after its zero and is not waited for (robots.commands.send); the
    # executor, seeing the stop, may cancel its goal first: the call then finds nothing left to cancel
    wait_for(cancelled, timeout=5, what="the stop's cancel_goal service call")
    wait_for(lambda: at_rest(nav_world, "tb3_nav2"), timeout=20, what="tb3_nav2 at rest")
    assert not nav_world.call(lambda: stack.nav.active)  # nav2's controller drives on no more
    assert wait_final(running, timeout=60).status == "cancelled"


@pytest.mark.parametrize("nav_world", [["husky"]], indirect=True)
def test_a_persons_stop_of_a_move_base_trip_ends_it_stopped_not_failed(nav_world, fleet_admin):
    """The stop cancels move_base's goal before it raises its flags (zeros first): the stack's "cancelled" is
    the person's stop, and the instruction says so (it once ended failed, "navigation cancelled")."""
    running = submit("move husky to A", fleet_admin)
    body = nav_world.fleet.robots["husky"].body
    wait_for(lambda: nav_world.call(lambda: abs(body.vx) > 0.05), timeout=60, what="husky moving")
    submit("stop husky", fleet_admin)
    wait_for(lambda: at_rest(nav_world, "husky"), timeout=20, what="husky at rest")
    ended = wait_final(running, timeout=60)
    assert ended.status == "cancelled", ended.outcome
    assert "husky: cancelled (stopped" in ended.outcome, ended.outcome


SLOW_TRIPS = {  # a trip through each kind of nav stack, and spot's, which the portal drives itself
    "tb3_nav2": "C",
    "husky": "A",
    "tiago": "G",
    "spot": "A",
}


@pytest.mark.parametrize("nav_world", [[name] for name in SLOW_TRIPS], indirect=True, ids=list(SLOW_TRIPS))
def test_slowly_is_kept_on_every_kind_of_robot(nav_world, fleet_admin, monkeypatch):
    """Each robot alone in its world (a robot asked to make way would drive at that step's own speed). Both
    trips take their speed from the one function (fleetcore.speed.pace), watched here."""
    (name,) = nav_world.urls.keys() & SLOW_TRIPS.keys()
    place = SLOW_TRIPS[name]
    asked, pace = [], speed.pace
    monkeypatch.setattr(speed, "pace", lambda said, limits: asked.append(said) or pace(said, limits))
    (normal, normal_peak), (slow, slow_peak) = (
        trips(nav_world, fleet_admin, {name: f"move {name}{word} to {place}"})[name]
        for word in ("", " slowly")
    )
    assert (normal.status, slow.status) == ("succeeded", "succeeded"), (normal.outcome, slow.outcome)
    assert 0.02 < slow_peak <= 0.6 * normal_peak, (slow_peak, normal_peak)
    assert asked == [None, "slow"]  # one pace per trip, the word as the step says it
    stack = nav_world.fleet.robots[name].navigator
    if name == "tb3_nav2":  # the limit was a SpeedLimit, lifted after the trip
        limits = nav_world.call(lambda: list(stack.speed_limits))
        assert {"percentage": True, "speed_limit": 35.0} in limits and limits[-1]["speed_limit"] == 0.0
    elif stack is not None:  # move_base: its planner's max_vel_x was lowered, and set back after the trip
        assert nav_world.call(lambda: stack.nav.max_vel_x) == pytest.approx(0.5)
