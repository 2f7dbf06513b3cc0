"""A subscription that wants one message a period (robots.rosbridge.client.throttle_for) against the simulator's
rosbridge: a TurtleBot's 20 Hz odometry arrives as every second message, none held and none in between."""

import asyncio
import itertools
import statistics

import pytest

from robots.rosbridge.client import RosbridgeClient, throttle_for
from simworker.testing import running_world


def test_the_throttle_is_under_the_period_so_a_message_a_few_ms_early_still_passes():
    assert throttle_for(100) == 75
    assert throttle_for(1000) == 750
    assert throttle_for(1) == 1  # never 0: that is "no throttle" to rosbridge


@pytest.mark.timeout(60)
def test_a_20_hz_odometry_followed_at_10_hz_arrives_as_every_second_message():
    with running_world("paper", endpoints=["turtlebot"]) as world:
        stamps: list[float] = []
        held: list[tuple[bool, int]] = []

        async def follow(world) -> None:
            client = RosbridgeClient(world.urls["turtlebot"], ping_interval=None)
            await client.connect()
            try:
                await client.subscribe(
                    "/odom",
                    "nav_msgs/Odometry",
                    lambda m: stamps.append(
                        m["header"]["stamp"]["secs"] + m["header"]["stamp"]["nsecs"] / 1e9
                    ),
                    throttle_for(100),
                )
                for _ in range(100):  # at most 5 s
                    if len(stamps) >= 21:
                        break
                    await asyncio.sleep(0.05)
                held.extend(await asyncio.to_thread(world.call, odometry_held, world.fleet))
            finally:
                await client.close()

        asyncio.run(follow(world))
    assert len(stamps) >= 21, f"{len(stamps)} messages in 5 s"
    gaps = [round(b - a, 3) for a, b in itertools.pairwise(stamps)]
    # the stamps are the simulator's own clock: its odometry is published every 0.05 s of it exactly
    assert statistics.median(gaps) == pytest.approx(0.1, abs=0.002), gaps
    assert min(gaps) >= 0.05 - 0.002, gaps  # never two of the same period: the throttle holds
    # none waits its turn in the server (a queue_length would hold each one, serialised, until a timer sends it)
    assert held == [(False, 0)]


def odometry_held(fleet) -> list[tuple[bool, int]]:
    """Each /odom subscription of the simulated rosbridge: (whether it holds messages, how many it holds now)."""
    return [
        (sub.holds, len(sub.held))
        for robot in fleet.robots.values()
        for sub in robot.server.subscribers.get("/odom", {}).values()
    ]
