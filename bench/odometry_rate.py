"""The odometry rate a 10 Hz follower gets from a busy simulator: rosbridge's throttle alone against a throttle
with a queue_length (robots.rosbridge.client.throttle_for, docs/scale.md, "sixth session").

    python -m bench.odometry_rate [--quick|--full] [--robots N] [--busy K] [--out DIR]

One simulator process with N TurtleBot3s on the paper world's `extra` endpoint (20 Hz odometry each) and one
client subscribed to every robot's odometry, alternately as a driven robot's link asks ("now": throttle_for(100) =
75 ms, queue_length 0) and as everything asked before d58d7ac and the links process asks still ("before": 100 ms,
queue_length 1), then at 90 ms; K busy processes beside them take cores away, as the rest of a cluster does. Messages per robot per second in each window. Writes odometry_rate.json.
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import statistics
import time
from collections import Counter

from bench import component
from fleetcore.world import load_world
from robots.rosbridge.client import RosbridgeClient, throttle_for
from simworker.testing import WorldProcess

MODES = {
    "quick": {"robots": 200, "busy": 2, "seconds": 5.0},
    "full": {"robots": 530, "busy": 2, "seconds": 8.0},
}
SETTLE_S = 2.0  # after subscribing, before counting
CONFIGS = [("now", throttle_for(100), 0), ("before", 100, 1)] * 2 + [("90 ms", 90, 0)]


def busy(until: float) -> None:
    """Take a core until then (a bounded loop)."""
    while time.monotonic() < until:
        pass


async def rate(url: str, names: list[str], throttle: int, queue: int, seconds: float) -> dict:
    """Messages per robot per second over `seconds`, subscribed so."""
    got: Counter = Counter()
    client = RosbridgeClient(url, ping_interval=None)
    await client.connect()
    try:
        for name in names:
            await client.subscribe(
                f"/{name}/odom", "nav_msgs/Odometry", lambda _m, n=name: got.update((n,)), throttle, queue
            )
        await asyncio.sleep(SETTLE_S)
        got.clear()
        started = time.monotonic()
        await asyncio.sleep(seconds)
        took = time.monotonic() - started
    finally:
        await client.close()
    hz = sorted(got[name] / took for name in names)
    return {"mean": round(statistics.fmean(hz), 2), "min": round(hz[0], 2), "max": round(hz[-1], 2)}


def run(cfg: dict) -> dict:
    windows = []
    with WorldProcess("paper", extra=cfg["robots"], endpoints=["extra"]) as sim:
        extra = load_world("paper").add_extra_robots(
            cfg["robots"]
        )  # the robots the simulator serves, by name
        names = [spec.name for spec in extra]
        until = time.monotonic() + len(CONFIGS) * (cfg["seconds"] + SETTLE_S + 5)
        hogs = [multiprocessing.Process(target=busy, args=(until,), daemon=True) for _ in range(cfg["busy"])]
        for hog in hogs:
            hog.start()
        try:
            for label, throttle, queue in CONFIGS:
                hz = asyncio.run(rate(sim.urls["extra"], names, throttle, queue, cfg["seconds"]))
                windows.append({"asked": label, "throttle_rate": throttle, "queue_length": queue, "hz": hz})
                print(f"bench.odometry_rate: {label} ({throttle} ms, queue {queue}): {hz}", flush=True)
        finally:
            for hog in hogs:
                hog.terminate()
    return {"config": cfg, "windows": windows}


def main(argv: list[str] | None = None) -> int:
    parser = component.parser(__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=None)
    parser.add_argument("--busy", type=int, default=None, help="busy processes beside the simulator")
    args = parser.parse_args(argv)
    cfg = dict(MODES[args.mode])
    cfg |= {k: getattr(args, k) for k in ("robots", "busy") if getattr(args, k) is not None}
    data = run(cfg) | {"when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    print(json.dumps(data["windows"], indent=1))
    print(f"bench.odometry_rate: wrote {component.write(args.out, 'odometry_rate.json', data)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
