"""The bare relay under the portal's hop (bench.relay): what it is sent reaches the simulated robot, as driven."""

import asyncio
import os
import tempfile
import time

import websockets

from bench.relay import Relay, RelayDriver
from experiments.probe import Reception, sim_robot_link
from simworker.testing import free_port, running_world


def test_the_relay_delivers_each_command_to_the_robot_it_names_and_the_robot_moves():
    with running_world("paper") as sim:
        link = sim_robot_link(sim, "turtlebot")
        reception = Reception(sim)
        reception.watch(link)
        start = sim.pose("turtlebot")
        log = os.path.join(tempfile.mkdtemp(), "relay.log")

        async def drive() -> tuple[float, float | None]:
            with Relay(free_port(), log) as relay:
                driver = RelayDriver(await websockets.connect(relay.url, ping_interval=None), [link])
                try:
                    await driver.warm_up([link])
                    t0 = await driver.start([link], 0.2, 0.123)
                    await asyncio.sleep(1.0)  # held: repeated every 0.2 s, as a held button
                    await driver.stop([link])
                    await asyncio.sleep(0.3)
                    return t0, reception.first_after(link, t0, angular=0.123)
                finally:
                    await driver.close()

        t0, arrived = asyncio.run(drive())
        assert (
            arrived is not None and arrived >= t0
        )  # the command with this angular speed reached the endpoint
        assert reception.first_after(link, arrived, zero=True) is not None  # and the stop's zero after it
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and abs(sim.pose("turtlebot")[2] - start[2]) < 0.05:
            time.sleep(0.05)
        assert abs(sim.pose("turtlebot")[2] - start[2]) >= 0.05  # the simulated robot turned
