"""Interpreter throughput: instructions per second on one core after the ontology is loaded.

`python -m bench.interpreter_throughput [--quick|--full]` migrates a temporary SQLite database (FLEET_VAR_DIR), adds the
paper's demo fleet, then interprets a mix of the acceptance rows. Writes bench/results/interpreter.json.
Without REDIS_URL the version check uses Django's local-memory cache instead of Redis.
"""

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import django
from django.conf import settings
from django.core.management import call_command

from bench import component
from interpreter.parser import interpret as parse

RESULT_FILE = "interpreter.json"
TSV = Path(__file__).resolve().parents[1] / "tests" / "data" / "instructions.tsv"
EXTRA = [
    "mvoe husy to the room 2 very fast",
    "move all turtlebots to (2, -1) slowly",
    "move husky to A and rotate 5 times then go to B",
    "please navigate tiago to x 1 y -1",
    "Proceed to sea and clean",
]


def setup_django() -> str:
    """Point Django at a fresh temporary database and migrate it; return the var dir."""
    var_dir = tempfile.mkdtemp(prefix="bench-interpreter-")
    os.environ["FLEET_VAR_DIR"] = var_dir
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")
    os.environ.pop("DATABASE_URL", None)
    django.setup()
    if not os.environ.get("REDIS_URL"):
        settings.CACHES = {"default": {"BACKEND": "django.core.cache.backends.locmem.LocMemCache"}}
    call_command("migrate", verbosity=0)
    return var_dir


def add_fleet() -> None:
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from places.models import Location, Map
    from robots.models import Robot

    robots = [("turtlebot", "turtlebot3_burger"), ("husky", "husky"), ("tiago", "tiago")]
    robots += [(f"robot{i}", "turtlebot3_burger") for i in range(1, 5)]
    for i, (name, model) in enumerate(robots):
        Robot.objects.create(name=name, model=model, drive="wheeled", endpoint=f"ws://127.0.0.1:{9090 + i}")
    the_map = Map.objects.create(name="paper", resolution=0.05, width=10, height=10, data=bytes(100))
    points = {"A": (2, 2), "B": (-2, 2), "C": (2, -2), "D": (5, 5), "E": (5, -5), "F": (0, 5), "G": (1, -1)}
    points |= {"H": (0, 1), "I": (-1, 1)}
    for name, (x, y) in points.items():
        Location.objects.create(map=the_map, name=name, x=x, y=y, kind="waypoint")
    for i in range(1, 5):
        Location.objects.create(map=the_map, name=f"Room {i}", x=i, y=-i, kind="room")


def instructions() -> list[str]:
    rows = [line.split("\t")[0] for line in TSV.read_text().splitlines() if line and not line.startswith("#")]
    return rows[1:] + EXTRA


def rate(fn, texts: list[str], seconds: float) -> tuple[float, int]:
    """Call fn over the texts repeatedly for about `seconds`; return (calls per second, calls)."""
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for text in texts:
            fn(text)
        n += len(texts)
    return n / (time.perf_counter() - start), n


def main(argv=None) -> dict:
    args = component.parser("interpreter throughput (--quick: 1 s per rate instead of 5 s)").parse_args(argv)
    seconds = 1.0 if args.mode == "quick" else 5.0
    setup_django()
    add_fleet()
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from interpreter.service import interpret, store

    start = time.perf_counter()
    grammar = store().get_grammar()
    cold_ms = (time.perf_counter() - start) * 1000
    texts = instructions()
    service_rate, n = rate(interpret, texts, seconds)
    parser_rate, _ = rate(lambda t: parse(t, grammar), texts, seconds)
    result = {
        "interpreter_per_s": round(service_rate),
        "parser_only_per_s": round(parser_rate),
        "instructions_measured": n,
        "distinct_instructions": len(texts),
        "ontology_load_ms": round(cold_ms, 1),
        "cache": "redis" if os.environ.get("REDIS_URL") else "locmem",
        "goal_per_s": 2000,
        "seconds": seconds,
    }
    component.write(args.out, RESULT_FILE, result)
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
