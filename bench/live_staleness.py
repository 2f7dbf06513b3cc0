"""Live-push staleness: a pose in the simulator's odometry -> seen by browser WebSocket clients of /ws/fleet/.

Staleness of one pose = time a client received it - the odometry stamp it carries (the simulator stamps in wall
time while it keeps real time). Run `python -m bench.live_staleness feed` as the pose feeder process.
"""

import asyncio
import json
import sys

import django
import websockets

from bench.frames import until
from experiments.stats import summarize
from portal.fanout import decode


async def client(url: str, cookie: str, origin: str, samples: list[float], stop: asyncio.Event) -> int:
    """One browser: log in by cookie, read every pushed batch, keep (received - stamped) per pose."""
    frames = 0
    async with websockets.connect(
        url, additional_headers={"Cookie": f"sessionid={cookie}", "Origin": origin}, max_size=None
    ) as ws:
        async for now, raw in until(ws, stop):
            frames += 1
            msg = json.loads(raw)
            if msg.get("type") == "fleet.poses":
                samples.extend((now - p["t"]) * 1000 for p in decode(msg) if p.get("t"))
    return frames


async def measure(ws_url: str, cookie: str, origin: str, clients: int, seconds: float) -> dict:
    samples: list[float] = []
    stop = asyncio.Event()
    tasks = [asyncio.create_task(client(ws_url, cookie, origin, samples, stop)) for _ in range(clients)]
    await asyncio.sleep(seconds)
    stop.set()
    frames = await asyncio.gather(*tasks, return_exceptions=True)
    errors = [repr(f) for f in frames if isinstance(f, BaseException)]
    return {
        "staleness_ms": summarize(samples),
        "frames": [f for f in frames if isinstance(f, int)],
        "errors": errors,
    }


def feed() -> None:
    """The pose feeder: every registered robot's odometry into robots.poses (what `robotlinks` does)."""
    django.setup()
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from robots.models import Robot
    from robots.poses import PoseHub, follow

    robots = list(Robot.objects.prefetch_related("bindings"))
    hub = PoseHub()
    for robot in robots:
        hub.track(robot.pk, robot.start_pose or None)
    asyncio.run(follow(robots, hub, asyncio.Event()))


if __name__ == "__main__":
    if sys.argv[1:] == ["feed"]:
        feed()
    else:
        sys.exit("usage: python -m bench.live_staleness feed   (bench.run starts it)")
