"""A robot whose link drops while it moves: the step fails "link lost", and the robot gets a zero when its
link is back (the links process sends it before anything else may command the robot).

The robot here has no command timeout: while its link is down it drives on with the last command it got,
which is what the zero on reconnection is for.
"""

import asyncio
import threading

import pytest

from alerts.models import Alert
from execution.instructions import submit
from execution.models import Instruction
from robots.links import LinkManager
from tests.execution.helpers import at_rest, parse, step, wait_final, wait_for, without_command_timeout

pytestmark = [pytest.mark.timeout(90), pytest.mark.slow]


@pytest.fixture
def links_process(turtle_world):
    """What `manage.py robotlinks` runs: one reconnecting link per endpoint, link status and alerts."""
    state, started = {}, threading.Event()

    async def main():
        state["manager"] = LinkManager(list(turtle_world.urls.values()))
        state["loop"] = asyncio.get_running_loop()
        started.set()
        await state["manager"].run()

    thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)
    thread.start()
    started.wait(5)
    yield state["manager"]
    state["loop"].call_soon_threadsafe(state["manager"].stop)
    thread.join(10)


def on_sim_loop(sim, coroutine):
    return asyncio.run_coroutine_threadsafe(coroutine, sim.loop).result(10)


def test_link_lost_while_moving_fails_the_step_and_the_robot_gets_a_zero_when_back(
    turtle_world, links_process, fleet_admin
):
    sim = turtle_world
    body = sim.fleet.robots["turtlebot"].body
    server = sim.fleet.servers["turtlebot"]
    without_command_timeout(sim, "turtlebot")
    wait_for(lambda: Alert.objects.count() == 0 and _online("turtlebot"), what="the link up")
    instruction = submit(
        "move turtlebot far", fleet_admin, parse=parse(step(["turtlebot"], 0.5, -0.5, "far"))
    )
    wait_for(lambda: sim.call(lambda: body.vx) > 0.1, timeout=40, what="driving")

    on_sim_loop(sim, server.stop())  # the endpoint goes away (rosbridge killed, Wi-Fi gone)
    final = wait_final(instruction, timeout=15)
    assert final.status == "failed" and "link lost" in final.outcome, final.outcome
    assert sim.call(lambda: body.vx) > 0.1  # nobody could reach it: still driving on the last command
    wait_for(
        lambda: Alert.objects.open().filter(kind="robot_offline", robot__name="turtlebot").exists(),
        what="offline alert",
    )

    on_sim_loop(sim, server.start("127.0.0.1"))  # back on the same port
    back_at = sim.call(lambda: sim.fleet.physics.time)
    wait_for(
        lambda: at_rest(sim, "turtlebot") and sim.call(lambda: body.cmd.stamp) > back_at,
        timeout=10,
        what="a zero on reconnection",
    )
    wait_for(lambda: _online("turtlebot"), what="online again")
    # the links process writes the robot online, then resolves its alert: a moment apart
    offline = wait_for(
        lambda: Alert.objects.filter(
            kind="robot_offline", robot__name="turtlebot", resolved_at__isnull=False
        ).first(),
        what="the offline alert resolved",
    )
    assert offline.resolution == "link up again"
    assert (
        Alert.objects.open()
        .filter(kind="step_failed", robot__name="turtlebot", message__contains="link lost")
        .exists()
    )
    assert Instruction.objects.get(pk=instruction.pk).status == "failed"


def _online(name: str) -> bool:
    from robots.models import Robot

    return Robot.objects.get(name=name).link_status == Robot.Link.ONLINE
