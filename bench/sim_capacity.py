"""How many robots one core keeps at real-time 50 Hz physics with 20 Hz odometry streamed to a subscriber.

`python -m bench.sim_capacity [--quick|--full]` writes bench/results/sim_capacity.json.

For each fleet size N the simulator runs alone in a child process pinned to CPU 0 (`--serve`), with N
TurtleBot3s on the `extra` endpoint of the paper world. This process, pinned to CPU 1, subscribes to every
robot's odometry on one connection and keeps every robot moving (a Twist per robot at 2 Hz). A size passes
when, over the measuring window, the physics ran at least 98% of the real-time steps, none started more
than 0.1 s late, and the subscriber received at least 95% of N x 20 odometry messages per second. The answer is the largest
passing N. Other work on the machine (other test runs) lowers the result; the JSON records the load.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from websockets.asyncio.client import connect

from bench import component
from fleetcore.world import load_world
from simworker.fleet import SimFleet

RESULT_FILE = "sim_capacity.json"
FULL_SIZES = [100, 250, 400, 500, 600, 700, 800, 1000]
QUICK_SIZES = [100, 300, 500]
STEP_HZ, ODOM_HZ, CMD_HZ = 50.0, 20.0, 2.0
MAX_LAG = 0.1  # seconds a step may start late (5 steps) before the size counts as not real time


def serve(n: int) -> None:
    """Child mode: run N extra robots, print the URL, then stats once a second until SIGTERM."""
    world = load_world("paper")
    world.extra["spacing"] = 0.3 if n > 500 else 0.45
    fleet = SimFleet(world, extra=n, endpoints=["extra"])

    async def report() -> None:
        while True:
            s = fleet.stats
            print(
                json.dumps(
                    {
                        "t": time.monotonic(),
                        "steps": s.steps,
                        "late": s.late_steps,
                        "resyncs": s.resyncs,
                        "max_lag": round(s.max_lag, 4),
                    }
                ),
                flush=True,
            )
            s.max_lag = 0.0  # each line reports the worst lag of the second before it
            await asyncio.sleep(1.0)

    tasks = []

    def ready(f: SimFleet) -> None:
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGTERM, f.request_stop)
        tasks.append(loop.create_task(report()))
        print("ready " + f.urls["extra"], flush=True)

    asyncio.run(fleet.run(on_ready=ready))


async def drive_and_count(url: str, n: int, warmup: float, window: float) -> dict:
    """Subscribe to every robot's odometry and keep them moving; count odometry during the window."""
    names = [f"/robot{5 + i}" for i in range(n)]
    async with connect(url, max_size=None, max_queue=None) as ws:
        for ns in names:
            await ws.send(json.dumps({"op": "subscribe", "topic": f"{ns}/odom", "type": "nav_msgs/Odometry"}))
        counts = {"n": 0}

        async def receive() -> None:
            async for _ in ws:
                counts["n"] += 1

        async def command() -> None:
            twist = json.dumps({"linear": {"x": 0.05}, "angular": {"z": 0.5}})
            frames = [f'{{"op":"publish","topic":"{ns}/cmd_vel","msg":{twist}}}' for ns in names]
            while True:
                for frame in frames:
                    await ws.send(frame)
                await asyncio.sleep(1.0 / CMD_HZ)

        tasks = [asyncio.create_task(receive()), asyncio.create_task(command())]
        await asyncio.sleep(warmup)
        start_count, start = counts["n"], time.monotonic()
        await asyncio.sleep(window)
        received, elapsed = counts["n"] - start_count, time.monotonic() - start
        for task in tasks:
            task.cancel()
    return {"odom_per_s": received / elapsed}


def measure(n: int, warmup: float, window: float) -> dict:
    """Run one fleet size and return whether it kept real time, with the numbers."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench.sim_capacity", "--serve", str(n)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).parent.parent,
    )
    _pin(proc.pid, 0)
    try:
        line = proc.stdout.readline().split()
        if not line or line[0] != "ready":
            raise RuntimeError(f"simulator for {n} robots did not start")
        stats: list[dict] = []
        reader = threading.Thread(
            target=lambda: [stats.append(json.loads(x)) for x in proc.stdout], daemon=True
        )
        reader.start()
        client = asyncio.run(drive_and_count(line[1], n, warmup, window))
        first = next(s for s in stats if s["t"] >= stats[-1]["t"] - window)
        last = stats[-1]
    finally:
        proc.terminate()
        proc.wait(10)
    span = last["t"] - first["t"]
    step_ratio = (last["steps"] - first["steps"]) / (span * STEP_HZ) if span else 0.0
    odom_ratio = client["odom_per_s"] / (n * ODOM_HZ)
    max_lag = max(s["max_lag"] for s in stats if s["t"] > first["t"])
    ok = (
        step_ratio >= 0.98
        and last["resyncs"] == first["resyncs"]
        and odom_ratio >= 0.95
        and max_lag <= MAX_LAG
    )
    return {
        "robots": n,
        "realtime": ok,
        "step_ratio": round(step_ratio, 3),
        "odom_ratio": round(odom_ratio, 3),
        "odom_per_s": round(client["odom_per_s"]),
        "late_steps": last["late"] - first["late"],
        "max_lag_s": max_lag,
    }


def _pin(pid: int, cpu: int) -> None:
    """Pin a process to one CPU when the machine has more than one (no-op elsewhere)."""
    if hasattr(os, "sched_setaffinity") and (os.cpu_count() or 1) > 1:
        os.sched_setaffinity(pid, {cpu})


def main(argv: list[str] | None = None) -> dict:
    parser = component.parser(__doc__.splitlines()[0])
    parser.add_argument("--serve", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        serve(args.serve)
        return {}
    _pin(0, 1)
    sizes, warmup, window = (QUICK_SIZES, 2.0, 4.0) if args.mode == "quick" else (FULL_SIZES, 3.0, 10.0)
    runs = []
    for n in sizes:
        runs.append(measure(n, warmup, window))
        print(json.dumps(runs[-1]), flush=True)
        if not runs[-1]["realtime"]:
            break
    passing = [r["robots"] for r in runs if r["realtime"]]
    result = {
        "sim_realtime_robots": max(passing, default=0),
        "goal": 500,
        "criteria": "physics >= 98% of 50 Hz steps, no step later than 0.1 s, no resync, >= 95% of N x 20 Hz odometry received",
        "mode": args.mode,
        "load_avg_1min": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        "runs": runs,
    }
    component.write(args.out, RESULT_FILE, result)
    print(json.dumps({k: result[k] for k in ("sim_realtime_robots", "mode", "load_avg_1min")}))
    return result


if __name__ == "__main__":
    main()
