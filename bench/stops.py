"""What a stop-all costs the web host that takes it: CPU seconds per stop of every robot, on a running cluster.

    sudo .venv/bin/python -m bench.cluster --robots 100 --rounds 1 --clients 0 --keep   # the cluster, left up
    sudo .venv/bin/python -m bench.stops --stops 10                                     # then this
    sudo .venv/bin/python -m deploy.cluster down

The dashboard's STOP for every robot, `--stops` times, `--every` seconds apart, on one socket to web1; the CPU of
web1's processes and of PostgreSQL's over that time, per stop and per robot stopped (the cost model's "doing",
README). The robots stand: a stop's zeros and bookkeeping are the same for a robot at rest.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import time

from bench.cluster import connect, drain, host_cpu
from deploy.cluster import Cluster
from deploy.cluster_client import Portal


async def measure(stops: int, every: float) -> dict:
    cluster = Cluster()
    portal = Portal(cluster.url("web1")).login()
    ids = [robot["id"] for robot in portal.robots().values()]
    ws = await connect(cluster.url("web1"), portal.session.cookies.get("sessionid"))
    reader = asyncio.create_task(drain(ws))
    await ws.send(json.dumps({"command": "stop", "robots": ids}))  # the socket's first: its checks read once
    await asyncio.sleep(every)
    before = {host: host_cpu(host) for host in ("web1", "db")}
    for _ in range(stops):
        await ws.send(json.dumps({"command": "stop", "robots": ids}))
        await asyncio.sleep(every)
    used = {host: host_cpu(host) - before[host] for host in before}
    reader.cancel()
    await ws.close()
    return {
        "robots": len(ids),
        "stops": stops,
        "every_s": every,
        "cpu_s": {host: round(seconds, 3) for host, seconds in used.items()},
        "ms_per_stop": {host: round(1000 * seconds / stops, 1) for host, seconds in used.items()},
        "ms_per_robot_stopped": {
            host: round(1000 * seconds / stops / len(ids), 3) for host, seconds in used.items()
        },
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stops", type=int, default=10)
    parser.add_argument("--every", type=float, default=1.0, help="seconds between stops")
    args = parser.parse_args(argv)
    print(json.dumps(asyncio.run(measure(args.stops, args.every)), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
