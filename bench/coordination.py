"""Fleet coordination in the warehouse world: robots sent at once on crossing routes, and allocation at scale.

`python -m bench.coordination [--quick|--full] [--counts N ...] [--executors K]` writes
bench/results/coordination.json:
{"coordination": {"<n>": {"contacts", "deadlocks", "completion", "makespan_s", "lone_s", "makespan_ratio",
 "failed", "finish_s" (seconds to each robot's end, simulated time), "touched" ([t, robot, robot] each contact),
 "lone_runs" ({robot: makespan_s alone})},
 "allocation_ms_1000": {"p50", "p99"}, "executors": {"processes", "database"}}, ...}.

For n = 2, 4, 8, 16, 32 robots (quick: 2, 4, 8) of mixed models (Huskies, TurtleBots, TIAGos with move_base;
not the Spots, whose go_to_pose the simulator does not serve), each gets a goal on the far side of the warehouse (robots from the west go east and the other way
round, so the routes cross), submitted together as one instruction per robot through
execution.instructions.submit, run by K executor processes (`manage.py executor`: an asyncio task per robot,
the robots spread over the processes by rendezvous hashing) against the simulator, itself in a process of its own (simworker.testing.WorldProcess):
what is measured is the traffic layer, not one interpreter's lock shared by the physics and 32 executors.
With DATABASE_URL naming a PostgreSQL server, the bench runs on a scratch database there (bench_coordination,
created afresh and dropped at the end); else on a SQLite file, which locks under many robots.
The scheduler process (`manage.py scheduler`) is not started: every instruction names its robot, which is free,
so nothing waits for allocation, and the executors themselves fail an instruction whose lock lapsed; its
watchdog would only add the stop of a robot whose executor died.

- contacts: robot-robot contacts counted by the simulator's physics (simworker.physics, a pymunk handler);
- deadlocks: wait-for cycles the traffic layer found (and broke by rerouting one robot), execution.traffic_state;
- completion: the share of robots whose instruction succeeded and that stand within 0.3 m of their goal;
- makespan: simulated seconds from submitting to the last robot done, against the longest lone run: of each
  model, the robot with the longest planned route runs alone from the same start; the longest of those measured
  is the lone run. Robots are put back on their start poses between runs (teleported in the
  simulator, which moves their odometry with them).

Allocation: dispatch.allocate among 1,000 synthetic robots (rows with bindings and poses, no simulator) on the
warehouse map, for a step to a random place, timed end to end (queries, branch-and-bound path planning).
"""

from __future__ import annotations

import math
import os
import random
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from urllib.parse import urlparse

import django
import psycopg
from django.core.management import call_command
from django.db import connection, connections
from django.utils import timezone

from bench import component
from fleet.processes import end, fleet_env, start
from fleetcore.catalog import model
from fleetcore.interpretation import Interpretation
from fleetcore.planning import Planner
from fleetcore.steps import Step
from fleetcore.world import load_world
from simworker.testing import WorldProcess

RESULT_FILE = "coordination.json"
EXECUTORS = 4  # executor processes (--executors): with 2 (16 robots each) one process's loop starved past its
# locks' time to live under 8 blocking threads planning at once, and its 16 robots failed "executor lost"
EXECUTOR_START_TIMEOUT = 60.0  # s: every executor is a live member
HOME_SETTLE_S = 0.5  # s: robots sent home publish their new odometry before their traffic is released
SCRATCH_DB = "bench_coordination"  # on DATABASE_URL's PostgreSQL server
POSTGRES_SCHEMES = {"postgres", "postgresql"}
MODES = {
    "quick": {"counts": [2, 4, 8], "time_scale": 2.0, "alloc_rounds": 10},
    "full": {"counts": [2, 4, 8, 16, 32], "time_scale": 2.0, "alloc_rounds": 50},
}
WORLD = "warehouse"
SPEED = "very fast"
GOAL_BAND = (11.0, 19.0)  # y range of the goals: the cross aisle and the north block's aisles
GOAL_X = (3.0, 27.0)  # x range of the goals: clear of the robots parked along the west and east walls
# Robots are taken round-robin from these groups, so any n mixes models. Spot is left out: its driver's
# go_to_pose (bound as its navigation) is not simulated, so a Spot never arrives (issue 16 saw it too).
FLEET_ORDER = ("husky", "tb", "tiago")


def admin(url: str, *statements: str) -> None:
    """Run statements on the PostgreSQL server of url, outside a transaction (as CREATE DATABASE must)."""
    with psycopg.connect(urlparse(url)._replace(scheme="postgresql").geturl(), autocommit=True) as conn:
        for statement in statements:
            conn.execute(statement)


@contextmanager
def database() -> Iterator[str]:
    """The DATABASE_URL the bench runs on: a scratch database on DATABASE_URL's PostgreSQL server (dropped at
    the end, with whatever connections are left), else a SQLite file in a temporary directory."""
    url = os.environ.get("DATABASE_URL", "")
    if urlparse(url).scheme not in POSTGRES_SCHEMES:
        with tempfile.TemporaryDirectory(prefix="bench-coord-") as tmp:
            yield f"sqlite:///{os.path.join(tmp, 'db.sqlite3')}"
        return
    drop = f"DROP DATABASE IF EXISTS {SCRATCH_DB} WITH (FORCE)"
    admin(url, drop, f"CREATE DATABASE {SCRATCH_DB}")
    try:
        yield urlparse(url)._replace(path=f"/{SCRATCH_DB}").geturl()
    finally:
        admin(url, drop)


def setup_django(database_url: str) -> None:
    """Django on the bench's database, with keys of its own (its executors' membership and wake-ups too).

    All of it is said in the environment, which the executors are started with (fleet.processes.fleet_env)."""
    tag = f"bench-coord-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    os.environ.update(
        DATABASE_URL=database_url,
        FLEET_EXEC_KEY_PREFIX=f"bench:coord:{os.getpid()}",
        FLEET_REDIS_PREFIX=tag,  # a portal on the same Redis sees none of the bench's poses and pushes
        FLEET_WORLD=WORLD,
    )
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "fleet.settings")
    django.setup()
    call_command("migrate", verbosity=0)


def wait_ready(procs: list, count: int) -> None:
    """Wait (bounded) until every executor is a live member, so that the first run does not time their start."""
    # Deferred: the executor module reads settings, which this bench points at its own database first.
    from execution import executor

    deadline = time.monotonic() + EXECUTOR_START_TIMEOUT
    while len(executor.live_members()) < count:
        if any(proc.poll() is not None for proc in procs):
            raise RuntimeError("an executor exited while starting (its log is above)")
        if time.monotonic() > deadline:
            raise RuntimeError(f"{count} executors not up within {EXECUTOR_START_TIMEOUT:g} s")
        time.sleep(0.2)


@contextmanager
def executors(count: int) -> Iterator[None]:
    """count executor processes (`manage.py executor`) sharing the bench's database, Redis and keys; each ended
    at the end (SIGTERM to its process group, SIGKILL after fleet.processes.STOP_GRACE_S)."""
    env, procs = fleet_env(), []
    try:
        for _ in range(count):
            procs.append(start([sys.executable, "manage.py", "executor"], env))
        wait_ready(procs, count)
        yield
    finally:
        for proc in procs:
            end(proc)


def pick(names: list[str], n: int) -> list[str]:
    """n robots, round-robin over the model groups (so any n mixes models)."""
    groups = [[name for name in names if name.startswith(prefix)] for prefix in FLEET_ORDER]
    out = []
    while len(out) < n and any(groups):
        for group in groups:
            if group and len(out) < n:
                out.append(group.pop(0))
    return out


def crossing_goals(world, names: list[str], rng: random.Random) -> dict[str, tuple[float, float]]:
    """Goals on the far side: the westmost robot gets the eastmost goal, and so on, so the routes cross.
    Goals are free cells for the biggest robot, apart by more than two of its radii."""
    specs = {r.name: r for r in world.robots}
    biggest = max(model(specs[n].model).circumscribed_radius for n in names)
    planner = Planner(world.map, biggest)  # room for the biggest robot to turn on the spot at its goal
    goals: list[tuple[float, float]] = []
    for _ in range(5000):
        if len(goals) == len(names):
            break
        p = (round(rng.uniform(*GOAL_X), 2), round(rng.uniform(*GOAL_BAND), 2))
        if planner.free(*planner.to_cell(*p)) and all(math.dist(p, q) > 2 * biggest + 0.4 for q in goals):
            goals.append(p)
    west_first = sorted(names, key=lambda n: specs[n].x)
    return dict(zip(west_first, sorted(goals, reverse=True), strict=True))


def register(sim) -> dict:
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from places.worlds import load_world_into_db
    from robots.models import Robot
    from robots.registration import register_endpoints

    results = register_endpoints(list(sim.urls.values()))
    if not all(r.ok for r in results):
        raise SystemExit(f"registration failed: {[getattr(r, 'error', r) for r in results]}")
    load_world_into_db(WORLD)
    return {robot.name: robot for robot in Robot.objects.all()}


def reset(sim, robots: dict, names) -> None:
    """Put robots back on their start poses (in the simulator, and in the portal's pose store and traffic)."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution import traffic_state

    sim.home(names)
    time.sleep(HOME_SETTLE_S)
    for name in names:
        traffic_state.release(robots[name], sim.pose(name))


def run_together(sim, robots: dict, goals: dict, user, time_scale: float, limit_s: float) -> dict:
    """Send every robot to its goal at once; wait; measure contacts, deadlocks, completion, makespan."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution import traffic_fleet, traffic_state
    from execution.instructions import submit
    from execution.models import Instruction

    contacts0, deadlocks0 = sim.contacts(), traffic_state.deadlocks()
    started, since = time.time(), timezone.now()
    sent = {}
    for name, (x, y) in goals.items():
        goal = {"name": f"G-{name}", "x": x, "y": y}
        parse = Interpretation.for_robots([name], "move", "bench: coordination", goal, speed=SPEED)
        sent[name] = submit(f"move {name} to G-{name}", user, parse=parse).pk
    finished: dict[str, float] = {}
    while len(finished) < len(sent) and time.time() - started < limit_s:
        for name, pk in sent.items():
            if name not in finished and Instruction.objects.get(pk=pk).is_final:
                finished[name] = time.time()
        time.sleep(0.2)
    # robots that made way, on their way back
    while traffic_fleet.busy_ids() and time.time() - started < limit_s:
        time.sleep(0.2)
    settled = time.time()
    rows = {name: Instruction.objects.get(pk=pk) for name, pk in sent.items()}
    reached = 0
    for name, row in rows.items():
        execution = row.executions.first()
        goal = execution.steps[0]["destination"] if execution else None
        near = goal is not None and math.dist(sim.pose(name)[:2], (goal["x"], goal["y"])) < 0.3
        reached += int(row.status == "succeeded" and near)
    makespan = (settled - started) * time_scale  # every robot done, those that made way back too
    return {
        "robots": len(goals),
        "contacts": sim.contacts() - contacts0,
        "deadlocks": traffic_state.deadlocks() - deadlocks0,
        "completion": round(reached / len(goals), 3),
        "makespan_s": round(makespan, 1),
        "failed": {name: row.outcome[-200:] for name, row in rows.items() if row.status != "succeeded"},
        "finish_s": {name: round((at - started) * time_scale, 1) for name, at in sorted(finished.items())},
        "touched": [list(contact) for contact in sim.touched(contacts0)],
        "made_way": list(
            Instruction.objects.filter(source="traffic", received_at__gte=since).values_list(
                "text", "outcome"
            )
        ),
    }


def longest_trips(robots: dict, names: list[str], starts: dict, goals: dict) -> list[str]:
    """The robot of each model with the longest planned route from its start (robots of one model drive at one
    speed): the lone runs. A time estimated across models (planned length over the robot's top speed, or its
    nav stack's pace) ranked badly: run o ran three Huskies alone, the quickest robots there are."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution import route

    longest: dict[str, tuple[float, str]] = {}
    for name in names:
        robot = robots[name]
        length = route.planned_length(robot, starts[name], goals[name]) or math.dist(
            starts[name], goals[name]
        )
        model = robot.model or name.rstrip("0123456789")
        longest[model] = max(longest.get(model, (0.0, "")), (length, name))
    return [name for _, name in longest.values()]


def crossing(cfg: dict) -> dict:
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from django.contrib.auth.models import User

    user = User.objects.create_superuser("bench", password="bench-coordination")
    world, rng, out = load_world(WORLD), random.Random(16), {}
    scale = cfg["time_scale"]
    with WorldProcess(WORLD, time_scale=scale) as sim:
        robots = register(sim)
        for n in cfg["counts"]:
            names = pick(sorted(robots), n)
            goals = crossing_goals(world, names, rng)
            reset(sim, robots, robots)
            starts = {name: sim.pose(name)[:2] for name in names}
            together = run_together(sim, robots, goals, user, scale, limit_s=400 / scale + 60)
            lone = {}
            for name in longest_trips(robots, names, starts, goals):
                reset(sim, robots, robots)
                alone = run_together(sim, robots, {name: goals[name]}, user, scale, limit_s=300 / scale + 60)
                lone[name] = alone["makespan_s"]
            together["lone_runs"] = lone
            together["lone_s"] = max(lone.values())
            together["makespan_ratio"] = round(together["makespan_s"] / together["lone_s"], 2)
            out[str(n)] = together
            print(f"[coordination] {n} robots: {together}", flush=True)
    return out


def allocation_ms(rounds: int) -> dict:
    """dispatch.allocate among 1,000 robots (synthetic rows, poses on free cells of the warehouse)."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution import dispatch
    from places.worlds import load_world_into_db
    from robots.models import Binding, Robot
    from robots.poses import store_poses

    load_world_into_db(WORLD)
    world, rng = load_world(WORLD), random.Random(1000)
    planner = Planner(world.map, 0.12)
    Robot.objects.filter(name__startswith="synthetic").delete()
    footprint = [[-0.1, -0.1], [-0.1, 0.1], [0.1, 0.1], [0.1, -0.1]]
    rows = Robot.objects.bulk_create(
        Robot(
            name=f"synthetic{i:04d}",
            endpoint=f"ws://synthetic/{i}",
            footprint=footprint,
            link_status="online",
            state="ready",
        )
        for i in range(1000)
    )
    Binding.objects.bulk_create(
        Binding(robot=robot, action=role, target=f"/{robot.name}/{role}")
        for robot in rows
        for role in ("move", "odometry")
    )
    poses = {}
    for robot in rows:
        while True:
            x, y = rng.uniform(0.5, 29.5), rng.uniform(0.5, 19.5)
            if planner.free(*planner.to_cell(x, y)):
                break
        poses[robot.pk] = {"id": robot.pk, "x": x, "y": y, "yaw": 0.0}
    store_poses(list(poses.values()))
    Robot.objects.exclude(name__startswith="synthetic").update(link_status="offline")
    times = []
    for _ in range(rounds):
        place = rng.choice(world.locations)
        step = Step.from_dict(
            {
                "action": "move",
                "robots": "any",
                "destination": {"name": place.name, "x": place.x, "y": place.y},
            }
        )
        t0 = time.perf_counter()
        dispatch.allocate(step)
        times.append((time.perf_counter() - t0) * 1000)
    times.sort()
    p99 = times[min(len(times) - 1, math.ceil(0.99 * len(times)) - 1)]
    return {"p50": round(statistics.median(times), 1), "p99": round(p99, 1), "robots": 1000, "rounds": rounds}


def arguments(argv: list[str] | None):
    """The components' command line, and which robot counts to run and on how many executor processes."""
    parser = component.parser(__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", help="robot counts to run (default: the mode's)")
    parser.add_argument("--executors", type=int, default=EXECUTORS, help="executor processes")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> dict:
    args = arguments(argv)
    cfg = {**MODES[args.mode], "counts": args.counts or MODES[args.mode]["counts"]}
    with database() as url:
        setup_django(url)
        started = time.time()
        data = {"mode": args.mode}
        with executors(args.executors):
            data["coordination"] = crossing(cfg)
        data["allocation_ms_1000"] = allocation_ms(cfg["alloc_rounds"])
        data["executors"] = {"processes": args.executors, "database": connection.vendor}
        data["seconds"] = round(time.time() - started)
        connections.close_all()
    component.write(args.out, RESULT_FILE, data)
    print(f"[coordination] wrote {args.out / RESULT_FILE}", flush=True)
    return data


if __name__ == "__main__":
    main(sys.argv[1:])
