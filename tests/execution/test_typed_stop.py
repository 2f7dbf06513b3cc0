"""A typed stop is the fast stop: flags and a zero Twist before any database write; unreachable robots delay nobody."""

import asyncio
import socket
import threading

import pytest

from execution import coordination, fast_stop
from execution.instructions import submit
from execution.models import Instruction
from robots.models import Robot
from robots.rosbridge import sync
from robots.rosbridge.errors import LinkDown
from tests.execution.helpers import wait_for

pytestmark = [pytest.mark.timeout(60), pytest.mark.slow, pytest.mark.usefixtures("seeded_ontology")]


class Silent:
    """A TCP server on 127.0.0.1 that accepts connections and never answers: a robot whose link hangs."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.url = f"ws://127.0.0.1:{self.sock.getsockname()[1]}"

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def silent():
    server = Silent()
    yield server
    server.close()


@pytest.fixture
def fresh_targets():
    """The process's stop targets as a fresh process has them: none loaded yet."""
    fast_stop.TARGETS.by_robot, fast_stop.TARGETS.loaded_at = {}, float("-inf")
    yield fast_stop.TARGETS
    fast_stop.TARGETS.by_robot = {}


def test_typed_stop_reaches_the_robot_even_when_the_database_write_fails(
    turtle_world, operator, fresh_targets, monkeypatch
):
    """The zero goes out before the instruction row is written: a database that fails afterwards stops nothing."""
    from execution.control import teleop

    teleop("turtlebot", operator, 0.2, 0.0)
    wait_for(
        lambda: turtle_world.call(lambda: turtle_world.fleet.robots["turtlebot"].body.cmd).vx > 0, what="move"
    )

    def broken(*_args, **_kwargs):
        raise RuntimeError("database gone")

    monkeypatch.setattr(Instruction.objects, "create", broken)
    with pytest.raises(RuntimeError, match="database gone"):
        submit("stop turtlebot", operator)
    robot = Robot.objects.get(name="turtlebot")
    assert coordination.flags(robot.pk)[0] > 0  # the stop flag is up: a running instruction halts
    wait_for(
        lambda: turtle_world.call(lambda: turtle_world.fleet.robots["turtlebot"].body.cmd).vx == 0.0, what="0"
    )
    assert not Instruction.objects.exists()  # and nothing half-written was left behind


def test_halt_everything_typed_stops_every_robot_and_is_recorded(turtle_world, operator, fresh_targets):
    instruction = submit("halt everything", operator, source="cli")
    assert instruction.status == Instruction.Status.SUCCEEDED, instruction.outcome
    assert "turtlebot: stopped" in instruction.outcome
    robot = Robot.objects.get(name="turtlebot")
    assert coordination.flags(robot.pk)[0] > 0


def test_an_unreachable_endpoint_holds_no_lock_over_the_others(turtle_world, silent):
    """While one caller waits for a link that never comes up, another gets its own link at once."""
    waiting_done = threading.Event()
    errors = []

    def wait_on_silent():
        try:
            sync.get_client(silent.url, connect_timeout=5.0)
        except LinkDown as exc:
            errors.append(exc)
        finally:
            waiting_done.set()

    thread = threading.Thread(target=wait_on_silent, daemon=True)
    thread.start()
    client = sync.get_client(turtle_world.urls["turtlebot"], connect_timeout=5.0)
    assert client.client.is_connected
    assert not waiting_done.is_set()  # the silent endpoint is still being waited for: no lock was shared
    thread.join(10)
    assert errors and "not connected" in str(errors[0])


def test_fast_stop_skips_an_unreachable_robot_and_stops_the_others(
    turtle_world, operator, silent, fresh_targets
):
    """A registered robot whose endpoint hangs gets its flag; the reachable one gets its zero too."""
    ghost = Robot.objects.create(name="ghost", endpoint=silent.url, link_status=Robot.Link.ONLINE)
    ghost.bindings.create(action="move", target="/cmd_vel", message_type="geometry_msgs/Twist")
    sync.get_client(
        turtle_world.urls["turtlebot"]
    )  # the process's link to the live robot is up, as in operation
    fresh_targets.load_now()
    sent = fast_stop.stop_blocking("all")
    assert sent == 1  # turtlebot's zero; the ghost's link is not up, so it is left to control.stop
    assert (
        coordination.flags(ghost.pk)[0] > 0 and coordination.flags(turtle_world.robots["turtlebot"].pk)[0] > 0
    )
    asyncio.run(asyncio.sleep(0))  # nothing is left waiting on this thread's loop
