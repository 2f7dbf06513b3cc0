"""The bound on one link's inbound frames: a rate, what exceeds it dropped and counted, listeners told."""

import asyncio
import json

import pytest
from websockets.asyncio.server import serve

from robots.rosbridge import inflow
from robots.rosbridge.client import RosbridgeClient


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def heard(monkeypatch):
    """What the flood listeners are told: (url, dropped so far, flooding now)."""
    calls = []
    monkeypatch.setattr(inflow, "LISTENERS", [lambda *args: calls.append(args)])
    return calls


def test_frames_beyond_the_rate_are_dropped_counted_and_said_once_then_every_report(heard):
    clock = Clock()
    bound = inflow.Inflow("ws://flood", rate=100, clock=clock)
    admitted = sum(bound.admit() for _ in range(150))  # a burst at one instant: one second's worth passes
    assert admitted == 100 and bound.dropped == 50 and bound.flooding
    assert heard == [("ws://flood", 1, True)]  # said when the dropping started, not for every frame
    clock.now += inflow.REPORT_S
    assert sum(bound.admit() for _ in range(110)) == 100 and bound.dropped == 60
    assert heard[-1] == ("ws://flood", 51, True)  # and again while it goes on, with the count then
    clock.now += inflow.QUIET_S + 1
    assert bound.admit() and not bound.flooding
    assert heard[-1] == ("ws://flood", 60, False)  # and when it is over


def test_a_link_flooded_beyond_its_rate_drops_the_excess_and_still_answers(heard, settings):
    """An endpoint sending far more than the rate: the client keeps taking its share and stays usable."""
    settings.FLEET_ROBOT_MAX_FRAMES_PER_S = 200

    async def flood(ws):
        frame = json.dumps({"op": "publish", "topic": "/odom", "msg": {"n": 1}})
        while True:
            await ws.send(frame)
            await asyncio.sleep(0)  # as fast as the loop allows

    async def main():
        async with serve(flood, "127.0.0.1", 0) as server:
            url = f"ws://127.0.0.1:{server.sockets[0].getsockname()[1]}"
            received = []
            async with RosbridgeClient(url, ping_interval=None) as client:
                await client.subscribe("/odom", "nav_msgs/Odometry", received.append)
                for _ in range(200):  # bounded: 2 s at most
                    if client.inflow.dropped > 500:
                        break
                    await asyncio.sleep(0.01)
                await client.publish("/cmd_vel", {"linear": {"x": 0.0}}, "geometry_msgs/Twist")
                return client.inflow.dropped, len(received), url

    dropped, taken, url = asyncio.run(asyncio.wait_for(main(), 20))
    assert dropped > 500 and taken > 0
    assert heard and heard[0][0] == url and heard[0][2] is True


def test_the_rate_grows_with_what_the_throttled_subscriptions_ask_for(heard):
    """A shard of 500 robots' odometry at 10 Hz is what the link asked for: admitted, no flood said."""
    clock = Clock()
    bound = inflow.Inflow("ws://shard", rate=100, clock=clock)
    for _ in range(500):
        bound.expect(10.0)
    clock.now += 1.0  # a second's worth of tokens at the new rate
    assert sum(bound.admit() for _ in range(5000)) == 5000 and not bound.flooding and heard == []
    assert sum(bound.admit() for _ in range(100 + 2 * 5000 + 50)) <= 100 + 2 * 5000  # bounded all the same
    assert bound.dropped > 0
    for _ in range(500):
        bound.expect(-10.0)  # unsubscribed: back to the setting's allowance
    assert bound.rate == 100


def test_a_client_counts_its_throttled_subscriptions_in_its_inflow_rate(settings):
    settings.FLEET_ROBOT_MAX_FRAMES_PER_S = 200

    async def main():
        client = RosbridgeClient("ws://127.0.0.1:9", reconnect=True, ping_interval=None)  # never connected
        odom = await client.subscribe("/odom", "nav_msgs/Odometry", lambda m: None, throttle_rate=100)
        await client.subscribe(
            "/scan", "sensor_msgs/LaserScan", lambda m: None
        )  # no fixed rate: shares the 200
        assert client.inflow.rate == 200 + inflow.HEADROOM * 10
        await client.unsubscribe(odom)
        assert client.inflow.rate == 200

    asyncio.run(main())
