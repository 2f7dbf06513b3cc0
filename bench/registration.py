"""Registration time for 1, 10 and 100 simulated robots; identification time for a 1,200-topic robot.

`python -m bench.registration [--quick|--full]` writes bench/results/registration.json:
{"registration_s": {"1", "10", "100"}, "reregistration_s": {...}, "identification_ms_1200_topics",
 "discovery_s_1200_topics", ...}. Goals: 100 robots in under 5 s; identification under 100 ms.

Registration = discovery through rosapi + identification + storing every robot, topic, node, service, param
and binding, into a private SQLite database (a temporary file, migrated first): 1 robot is the paper world's
`turtlebot` endpoint; 10 and 100 are the simulator's `extra` namespaced robots on one endpoint.
Identification is timed on the Graph discovery returned for a 1,200-topic endpoint (100 nodes).
"""

from __future__ import annotations

import asyncio
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import django
from django.core.management import call_command

from bench import component
from robots.discovery import discover
from robots.identify import identify
from simworker import rosapi
from simworker.graph import Graph
from simworker.server import RosbridgeServer
from simworker.testing import running_world

RESULT_FILE = "registration.json"
MODES = {"quick": {"repeats": 1, "ident_runs": 20}, "full": {"repeats": 3, "ident_runs": 200}}


def setup_django(db_path: str) -> None:
    os.environ["DATABASE_URL"] = f"sqlite:///{db_path}"
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")
    django.setup()
    call_command("migrate", verbosity=0)


def time_registration(url: str, repeats: int) -> tuple[float, float, int]:
    """Median seconds of a first registration and of a re-registration; robots registered."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from robots.models import Robot
    from robots.registration import register_endpoints

    first, again, robots = [], [], 0
    for _ in range(repeats):
        Robot.objects.all().delete()
        t0 = time.perf_counter()
        (result,) = register_endpoints([url])
        first.append(time.perf_counter() - t0)
        if not result.ok:
            raise SystemExit(f"registration failed: {result.error}")
        t0 = time.perf_counter()
        register_endpoints([url])
        again.append(time.perf_counter() - t0)
        robots = len(result.robots)
    return statistics.median(first), statistics.median(again), robots


def registration_times(repeats: int) -> dict:
    out = {"registration_s": {}, "reregistration_s": {}, "robots": {}}
    cases = [("1", "turtlebot", 0), ("10", "extra", 10), ("100", "extra", 100)]
    for label, key, extra in cases:
        with running_world("paper", extra=extra, endpoints=[key]) as sim:
            first, again, robots = time_registration(sim.urls[key], repeats)
        out["registration_s"][label] = round(first, 3)
        out["reregistration_s"][label] = round(again, 3)
        out["robots"][label] = robots
        print(f"[registration] {robots} robots: {first:.3f} s (again {again:.3f} s)", flush=True)
    return out


def big_endpoint(topics: int = 1200):
    """A rosbridge endpoint (the simulator's server and rosapi) showing one robot with `topics` topics."""
    graph = Graph(1, time.time)
    graph.add_subscriber("/base_driver", "/cmd_vel", "geometry_msgs/Twist")
    graph.add_publisher("/base_driver", "/odom", "nav_msgs/Odometry")
    for i in range(topics - 2):
        graph.add_publisher(
            f"/sensor_node_{i % 100}", f"/sensors/group_{i % 40}/reading_{i}", "std_msgs/Float32"
        )
    server = RosbridgeServer("big", graph, 0)
    rosapi.finish(graph)
    return server


async def identification_time(runs: int) -> dict:
    server = big_endpoint()
    await server.start("127.0.0.1")
    try:
        t0 = time.perf_counter()
        (graph,) = await discover(f"ws://127.0.0.1:{server.port}")
        discovery = time.perf_counter() - t0
    finally:
        await server.stop()
    samples = []
    for _ in range(runs):
        t0 = time.perf_counter()
        results = identify(graph)
        samples.append((time.perf_counter() - t0) * 1000)
    assert results["move"].target == "/cmd_vel", results["move"]
    print(
        f"[registration] 1,200 topics: discovery {discovery:.3f} s, identification {statistics.median(samples):.2f} ms"
    )
    return {
        "identification_ms_1200_topics": round(statistics.median(samples), 3),
        "identification_ms_1200_topics_max": round(max(samples), 3),
        "discovery_s_1200_topics": round(discovery, 3),
        "topics": len(graph.topics),
    }


def main(argv: list[str] | None = None) -> int:
    args = component.parser(__doc__.splitlines()[0]).parse_args(argv)
    mode = args.mode
    cfg = MODES[mode]
    with tempfile.TemporaryDirectory() as tmp:
        setup_django(str(Path(tmp) / "bench.sqlite3"))
        data = {"mode": mode, **registration_times(cfg["repeats"])}
    data.update(asyncio.run(identification_time(cfg["ident_runs"])))
    data["goals"] = {"registration_s_100_max": 5.0, "identification_ms_max": 100.0}
    data["met"] = {
        "registration_100": data["registration_s"]["100"] < 5.0,
        "identification": data["identification_ms_1200_topics"] < 100.0,
    }
    data["cpus"] = os.cpu_count()
    data["load"] = os.getloadavg()[0]
    print(f"wrote {component.write(args.out, RESULT_FILE, data)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
