"""The cost of a robot (issue 35): CPU seconds per robot per second of each process kind, on one host.

    python -m bench.cost [--quick|--full] [--out DIR] [--robots N] [--clients C] [--driven K] [--window S]

One simulator process (N TurtleBot3s on the paper world's `extra` endpoint, registered through the portal's own
identification) and a private portal as `make run` has it (web, executor, instructions worker, control worker,
links, scheduler). Every robot turns all along (a Twist every 0.5 s from this process, which is not measured). CPU
(user + system, children included) of each process is read with psutil over three windows:

- base: no browser, no instruction: the simulator, the links process, the scheduler, each per robot;
- clients: C dashboards on /ws/fleet/ (frames counted, not decoded): the web process's extra CPU per client per
  robot;
- driven: K robots under a turn_by instruction (the others still teleoped): the executor's and the scheduler's
  extra CPU per driven robot.

The model: cores = N x (sim + links + C x web_per_client + driven share x (executor + scheduler_driven)) + fixed;
so a host of H cores carries N = H / (that sum per robot). Writes cost.json (bench/results by default).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import psutil
import websockets

from bench import component, frames
from bench.portal import Portal
from fleetcore.interpretation import Interpretation
from robots.rosbridge import RosbridgeClient
from simworker.testing import WorldProcess

RESULT_FILE = "cost.json"
MODES = {
    "quick": {"robots": 100, "clients": 10, "driven": 10, "window": 15.0},
    "full": {"robots": 200, "clients": 20, "driven": 20, "window": 30.0},
}
TURN = 0.3  # rad/s every robot turns at while teleoped
SETTLE_S = 12.0  # s after the processes start before the first window (imports, links, first subscriptions)
HOST_CORES = 32  # the host docs/scale.md's formula is written for


class CpuMeter:
    """CPU seconds (user + system, children included) used so far by each named process."""

    def __init__(self, pids: dict[str, int]) -> None:
        self.procs = {kind: psutil.Process(pid) for kind, pid in pids.items()}

    def read(self) -> dict[str, float]:
        used = {}
        for kind, proc in self.procs.items():
            total = 0.0
            for p in [proc, *proc.children(recursive=True)]:
                with contextlib.suppress(psutil.Error):
                    times = p.cpu_times()
                    total += times.user + times.system
            used[kind] = total
        return used

    async def window(self, seconds: float) -> dict[str, float]:
        """Cores used by each process over the next `seconds` (CPU seconds per wall second)."""
        before, t0 = self.read(), time.monotonic()
        await asyncio.sleep(seconds)
        after, wall = self.read(), time.monotonic() - t0
        return {kind: round((after[kind] - before[kind]) / wall, 4) for kind in after}


async def turn_all(clients: dict, robots: list[dict], stop: asyncio.Event, skip: set[str]) -> None:
    """Keep every robot not in `skip` turning: a Twist to each every 0.5 s (the teleop a person holds)."""
    twist = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": TURN}}
    while not stop.is_set():
        for robot in robots:
            if robot["name"] not in skip:
                await clients[robot["url"]].publish(robot["cmd"], twist, "geometry_msgs/Twist")
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 0.5)


async def dashboard(
    url: str, cookie: str, origin: str, seen: dict, stop: asyncio.Event, deflate: bool
) -> None:
    """One browser on the dashboard: counts the fleet.poses frames and poses it is pushed (rows, not made into
    poses); it offers permessage-deflate as browsers do, unless told not to."""
    headers = {"Cookie": f"sessionid={cookie}", "Origin": origin}
    compression = "deflate" if deflate else None
    async with websockets.connect(
        url, additional_headers=headers, max_size=None, compression=compression
    ) as ws:
        async for _, raw in frames.until(ws, stop):
            if '"fleet.poses"' in raw:
                seen["frames"] += 1
                seen["poses"] += len(json.loads(raw).get("rows") or [])


def register(url: str) -> list[dict]:
    """Register the endpoint through the portal's identification; the robots with their move topic."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from robots.models import Robot
    from robots.registration import register_endpoints

    (record,) = register_endpoints([url])
    if not record.ok:
        raise RuntimeError(f"registration of {url} failed: {record.error}")
    robots = []
    for robot in Robot.objects.filter(endpoint=url).prefetch_related("bindings"):
        Robot.objects.filter(pk=robot.pk).update(state=Robot.State.READY)
        move = next(b for b in robot.bindings.all() if b.action == "move")
        robots.append({"id": robot.pk, "name": robot.name, "url": url, "cmd": move.target})
    return robots


def drive(names: list[str], user) -> list[int]:
    """One turn_by instruction per robot (3600 degrees: longer than the window), as the API submits it."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution.instructions import submit

    ids = []
    for name in names:
        parse = Interpretation.for_robots([name], "turn_by", "bench: cost", amount=3600.0)
        ids.append(submit(f"turn {name} by 3600 degrees", user, "api", parse).pk)
    return ids


def statuses(ids: list[int]) -> dict[str, int]:
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution.models import Instruction

    return dict(Counter(Instruction.objects.filter(pk__in=ids).values_list("status", flat=True)))


async def measure(portal, sim, robots: list[dict], cfg: dict) -> dict:
    clients = {}
    for url in {r["url"] for r in robots}:
        clients[url] = RosbridgeClient(url, ping_interval=None)
        await clients[url].connect()
    stop, skip = asyncio.Event(), set()
    turning = asyncio.create_task(turn_all(clients, robots, stop, skip))
    pids = {"sim": sim.process.pid, **{k: p.pid for k, p in portal.procs.items()}}
    if portal.redis is not None:  # the embedded Redis: what the executors' and the hub's calls cost it
        pids["redis"] = portal.redis.pid
    meter = CpuMeter(pids)
    await asyncio.sleep(SETTLE_S)  # the processes started, the links subscribed
    out = {"base": await meter.window(cfg["window"])}
    out["clients"], out["live"], profile = await with_clients(portal, meter, cfg)
    if profile:
        out["profile_clients"] = profile
    driven = [r["name"] for r in robots[: cfg["driven"]]]
    skip.update(driven)
    ids = await asyncio.to_thread(drive, driven, portal.user)
    await asyncio.sleep(3.0)  # the executors started, their links opened
    spies = spy(meter, cfg, "driven")
    out["driven"] = await meter.window(cfg["window"])
    if spies:
        out["profile_driven"] = await asyncio.to_thread(profiles, spies)
    out["instructions"] = await asyncio.to_thread(statuses, ids)
    stop.set()
    await turning
    for client in clients.values():
        await client.close()
    return out


async def with_clients(portal, meter: CpuMeter, cfg: dict) -> tuple[dict, dict, dict]:
    """The window with C dashboards connected; what they were pushed (frames and poses per second each)."""
    cookie = await asyncio.to_thread(portal.session_cookie)
    stop = asyncio.Event()
    seen = [{"frames": 0, "poses": 0} for _ in range(cfg["clients"])]
    url = f"{portal.ws_url}/ws/fleet/"
    deflate = not cfg.get("no_deflate")
    tasks = [asyncio.create_task(dashboard(url, cookie, portal.http_url, s, stop, deflate)) for s in seen]
    await asyncio.sleep(3.0)
    for s in seen:
        s["frames"] = s["poses"] = 0
    spies = spy(meter, cfg, "clients")
    window = await meter.window(cfg["window"])
    profile = await asyncio.to_thread(profiles, spies) if spies else {}
    stop.set()
    done = await asyncio.gather(*tasks, return_exceptions=True)
    live = {
        "frames_per_s_per_client": [round(s["frames"] / cfg["window"], 1) for s in seen],
        "poses_per_s_per_client": [round(s["poses"] / cfg["window"], 1) for s in seen],
        "errors": [repr(d) for d in done if isinstance(d, BaseException)][:3],
    }
    return window, live, profile


def spy(meter: CpuMeter, cfg: dict, window: str) -> dict:
    """With --profile: py-spy samples each process (the thread holding the GIL: Python CPU) through the driven window (their CPU figures then include
    the sampling's cost: a profile run is not a measurement run). {kind: (process, its collapsed-stacks file)}."""
    if not cfg.get("profile"):
        return {}
    out = Path(cfg["profile"]) / window
    out.mkdir(parents=True, exist_ok=True)
    spy_bin = Path(sys.executable).parent / "py-spy"
    spies = {}
    for kind, proc in meter.procs.items():
        path = out / f"{kind}.txt"
        cmd = [str(spy_bin), "record", "-p", str(proc.pid), "-d", str(int(cfg["window"])), "-r", "50"]
        cmd += ["-f", "raw", "-o", str(path), "--subprocesses", "--nonblocking", "--gil"]
        spies[kind] = (subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL), path)
    return spies


def profiles(spies: dict, top: int = 12) -> dict[str, list[str]]:
    """Each process's functions by the share of its samples they were on the stack in (inclusive), top first."""
    out = {}
    for kind, (proc, path) in spies.items():
        proc.wait(timeout=120)
        inclusive, total = Counter(), 0
        for line in path.read_text().splitlines() if path.exists() else ():
            stack, _, count = line.rpartition(" ")
            if not count.isdigit():  # py-spy's own notes ("... sends.")
                continue
            functions = {f.split(" (")[0] + " " + f.split("/")[-1].rstrip(")") for f in stack.split(";")}
            total += int(count)
            for frame in functions:
                inclusive[frame] += int(count)
        out[kind] = [f"{100 * n / total:.0f}% {f}" for f, n in inclusive.most_common(top)] if total else []
    return out


def model(m: dict, cfg: dict, robots: int) -> dict:
    """ms of CPU per second per robot of each kind, and the robots a HOST_CORES host carries."""
    base, clients, driven = m["base"], m["clients"], m["driven"]
    per = {
        "sim_per_robot": base["sim"] / robots,
        "links_per_robot": base["links"] / robots,
        "scheduler_per_robot": base["scheduler"] / robots,
        "web_idle_per_robot": base["web"] / robots,
        "web_per_client_per_robot": max(0.0, clients["web"] - base["web"]) / cfg["clients"] / robots,
        "executor_per_driven_robot": max(0.0, driven["executor"] - base["executor"]) / cfg["driven"],
        "scheduler_per_driven_robot": max(0.0, driven["scheduler"] - base["scheduler"]) / cfg["driven"],
        "redis_per_robot": base.get("redis", 0.0) / robots,
        "redis_per_driven_robot": max(0.0, driven.get("redis", 0.0) - base.get("redis", 0.0)) / cfg["driven"],
        "sim_per_driven_robot": max(0.0, driven["sim"] - base["sim"]) / cfg["driven"],
    }
    ms = {k: round(v * 1000, 3) for k, v in per.items()}
    fixed = base["executor"] + base["worker"] + base["control"]
    share = cfg["driven"] / robots

    def per_robot(c: int) -> float:
        return (
            per["sim_per_robot"] + per["links_per_robot"] + per["scheduler_per_robot"]
            + per["web_idle_per_robot"] + c * per["web_per_client_per_robot"] + per["redis_per_robot"]
            + share * (per["executor_per_driven_robot"] + per["scheduler_per_driven_robot"]
                       + per["redis_per_driven_robot"] + per["sim_per_driven_robot"])
        )  # fmt: skip

    carries = {str(c): int((HOST_CORES - fixed) / per_robot(c)) for c in (0, 1, cfg["clients"], 50)}
    return {
        "ms_per_s": ms,
        "fixed_cores": round(fixed, 3),
        "driven_share": share,
        "cpu_ms_per_s_per_robot_measured": round(1000 * sum(driven.values()) / robots, 3),
        f"robots_on_{HOST_CORES}_cores_by_clients": carries,
    }


def run(cfg: dict) -> dict:
    portal = Portal()
    try:
        portal.setup()
        with WorldProcess("paper", extra=cfg["robots"], endpoints=["extra"]) as sim:
            robots = register(sim.urls["extra"])
            portal.start_web()
            portal.start_worker()
            portal.start_links()
            portal.start_scheduler()
            measured = asyncio.run(measure(portal, sim, robots, cfg))
    finally:
        portal.close()
    return {"robots": len(robots), **cfg, **measured, "model": model(measured, cfg, len(robots))}


def compare(before: Path, cfg: dict, rounds: int, out: Path) -> dict:
    """Before/after in one run: this bench alternately in `before` (another checkout, e.g. `git worktree add
    /tmp/before HEAD~1`) and in this tree, `rounds` times each, on the same machine under the same load; the
    ratio after/before of each kind's cost (ms per s per robot, the rounds' medians)."""
    here = Path(__file__).resolve().parent.parent
    args = [f"--{k}={v}" for k, v in cfg.items() if k in MODES["quick"]]
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    for _ in range(rounds):
        for label, tree in (("before", before), ("after", here)):
            tmp = Path(tempfile.mkdtemp(prefix=f"cost-{label}-"))
            cmd = [sys.executable, "-m", "bench.cost", *args, "--out", str(tmp)]
            subprocess.run(cmd, cwd=tree, check=True, timeout=900)
            runs[label].append(json.loads((tmp / RESULT_FILE).read_text()))
    median = {
        label: {
            k: statistics.median(r["model"]["ms_per_s"][k] for r in rs) for k in rs[0]["model"]["ms_per_s"]
        }
        for label, rs in runs.items()
    }
    total = {
        label: statistics.median(r["model"]["cpu_ms_per_s_per_robot_measured"] for r in rs)
        for label, rs in runs.items()
    }
    ratio = {k: round(median["after"][k] / v, 2) if v else None for k, v in median["before"].items()}
    data = {"config": cfg, "rounds": rounds, "before_tree": str(before), "ms_per_s_before": median["before"],
            "ms_per_s_after": median["after"], "ratio_after_before": ratio, "cpu_ms_per_s_per_robot": total,
            "runs": runs, "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}  # fmt: skip
    component.write(out, "cost_compare.json", data)
    return data


def main(argv: list[str] | None = None) -> int:
    parser = component.parser(__doc__.splitlines()[0])
    for name, kind in (("robots", int), ("clients", int), ("driven", int), ("window", float)):
        parser.add_argument(f"--{name}", type=kind, default=None)
    parser.add_argument("--profile", default="", help="a dir: py-spy each process in the driven window")
    parser.add_argument("--no-deflate", action="store_true", help="dashboards that do not offer compression")
    parser.add_argument(
        "--before", type=Path, help="another checkout: before/after in one run (cost_compare.json)"
    )
    parser.add_argument("--rounds", type=int, default=2, help="with --before: runs of each, alternating")
    args = parser.parse_args(argv)
    cfg = dict(MODES[args.mode])
    cfg |= {k: getattr(args, k) for k in cfg if getattr(args, k) is not None}
    if args.profile:
        cfg["profile"] = args.profile
    if args.no_deflate:
        cfg["no_deflate"] = True
    if args.before:
        compared = compare(args.before, cfg, args.rounds, args.out)
        print(
            json.dumps({k: compared[k] for k in ("ratio_after_before", "cpu_ms_per_s_per_robot")}, indent=1)
        )
        return 0
    load = os.getloadavg()
    data = run(cfg)
    data |= {"mode": args.mode, "load_average_at_start": [round(x, 2) for x in load], "cores": os.cpu_count()}
    data["cost_ms_per_s_per_robot"] = data["model"]["ms_per_s"]
    data["when"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    path = component.write(args.out, RESULT_FILE, data)
    print(json.dumps(data["model"], indent=1))
    print(f"bench.cost: wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
