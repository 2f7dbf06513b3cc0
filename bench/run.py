"""`python -m bench.run --quick|--full`: every experiment against a fresh simulated fleet and a private portal.

Each experiment is independent: one that cannot run (a part of the system missing, an error) is recorded with
the reason and the others still run. Results: bench/results/ (summary.json, <experiment>.json, REPORT.md, PNGs).
"""

import argparse
import asyncio
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

import websockets

from bench import execution, relay, report
from bench.hand import hand_register
from bench.live_staleness import measure
from bench.portal import Portal
from experiments.drivers import DirectDriver, PortalDriver, Unavailable
from experiments.probe import Reception, sim_robot_link, watch_odometry
from experiments.response import ODOM_WATCH_MAX, command_latency, robots_scale, speed_grid
from experiments.stats import profile_calls
from robots.rosbridge import RosbridgeClient
from simworker.testing import free_port, running_world

RESULTS = Path(__file__).resolve().parent / "results"
MODES = {
    "quick": {
        "repeats": 1,
        "hold_s": 0.5,
        "counts": [1, 2, 4, 8, 16],
        "latency": (1, 10, 100),
        "rounds": 10,
        "extra": 196,
        "stale_robots": 200,
        "stale_s": 5.0,
        "component_timeout": 60,
        "time_scale": 8.0,  # the execution experiments' world runs 8x faster than real time
        "success_trials": 1,
        "stop_repeats": 3,
        "typed_stop_trials": 3,  # rounds of each kind of stop (typed, typed for one robot, socket, button)
        "exec_limit_s": 90,
        "typed_stop_limit_s": 240,
    },
    "full": {
        "repeats": 5,
        "hold_s": 1.0,
        "counts": [1, 2, 4, 8, 16, 32, 64, 128, 256],
        "latency": (1, 10, 100),
        "rounds": 50,
        "extra": 252,
        "stale_robots": 200,
        "stale_s": 20.0,
        "component_timeout": 600,
        "time_scale": 8.0,  # as quick: times are reported in simulated seconds; 20 trials at real time take hours
        "success_trials": 20,
        "stop_repeats": 10,
        "typed_stop_trials": 10,
        "exec_limit_s": 3600,
        "typed_stop_limit_s": 3600,
    },
}
COMPONENTS = {  # bench module (owned by its component's engineer) -> (the JSON it writes, summary keys in it)
    "sim_capacity": ("sim_capacity.json", ("sim_realtime_robots",)),
    "interpreter_throughput": ("interpreter.json", ("interpreter_per_s",)),
    "registration": ("registration.json", ("registration_s", "identification_ms_1200_topics")),
    "coordination": ("coordination.json", ("coordination", "allocation_ms_1000")),
    "stop_faults": (
        "stop_faults.json",
        ("stop_faults",),
    ),  # a person's stop under Redis, database, link faults
    "cost": ("cost.json", ("cost_ms_per_s_per_robot",)),  # CPU per robot per second of each process kind
}
COMPONENT_TIMEOUTS = {"coordination": {"quick": 900, "full": 3600}}  # s: robots drive there in simulated time


def result(title: str, status: str = "ok", **fields) -> dict:
    return {"title": title, "status": status, "reason": "", "notes": [], **fields}


class Bench:
    """One run: the simulated world, the rosbridge clients, the portal, and every result so far."""

    def __init__(self, mode: str, sim, portal) -> None:
        self.mode, self.cfg, self.sim, self.portal = mode, MODES[mode], sim, portal
        self.results: dict[str, dict] = {}
        self.reception = Reception(sim)
        self.clients: dict[str, object] = {}
        self.watches: dict = {}
        self.stack = contextlib.ExitStack()  # the execution experiments' own world, started on demand
        self.exec_sim = None
        self.time_scale = self.cfg["time_scale"]
        self.lane_pos: dict[str, int] = {}  # robot -> index of the lane target it last went to
        self.outcomes: list[dict] = []

    async def client(self, url: str):
        if url not in self.clients:
            self.clients[url] = RosbridgeClient(url, ping_interval=None)
            await self.clients[url].connect()
        return self.clients[url]

    async def links(self, names: list[str], watch: int = ODOM_WATCH_MAX):
        links = [sim_robot_link(self.sim, n) for n in names]
        for i, link in enumerate(links):
            self.reception.watch(link)
            await self.client(link.url)
            if link.name not in self.watches and i < watch:
                self.watches[link.name] = await watch_odometry(self.clients[link.url], link)
        return links

    def fleet_names(self, n: int) -> list[str]:
        """robot1..robotN: the namespaced TurtleBot3s (1-4 on one endpoint, the extras on another)."""
        return [f"robot{i}" for i in range(1, n + 1) if f"robot{i}" in self.sim.fleet.robots]

    async def guarded(self, name: str, title: str, coro) -> None:
        """Run one experiment; record why it did not run rather than stop the bench."""
        started = time.time()
        print(f"[bench] {name}: {title} ...", flush=True)
        try:
            self.results[name] = await coro
        except Unavailable as exc:
            self.results[name] = result(title, "skipped", reason=str(exc))
        except Exception as exc:  # one experiment's failure is reported, the others still run
            self.results[name] = result(
                title,
                "error",
                reason=f"{type(exc).__name__}: {exc}",
                traceback=traceback.format_exc()[-3000:],
            )
        self.results[name]["seconds"] = round(time.time() - started, 1)
        print(
            f"[bench] {name}: {self.results[name]['status']} in {self.results[name]['seconds']} s "
            f"{self.results[name].get('reason', '')}",
            flush=True,
        )

    # ----- experiments -----
    async def exp1_direct(self) -> dict:
        (link,) = await self.links(["turtlebot"])
        driver = DirectDriver(self.clients)
        grid = await speed_grid(
            driver, link, self.watches, self.reception, self.cfg["repeats"], self.cfg["hold_s"], table=3
        )
        await driver.close()
        return result(
            "Experiment 1: direct rosbridge publish (no portal), Table 3",
            cells=grid.pop("cells"),
            notes=[grid["cap"]],
            **grid,
        )

    async def exp4_scale_direct(self) -> dict:
        links = await self.links(self.fleet_names(max(self.cfg["counts"])))
        driver = DirectDriver(self.clients)
        counts = [n for n in self.cfg["counts"] if n <= len(links)]
        scale = await robots_scale(
            driver, links, self.watches, self.reception, counts, self.cfg["repeats"], self.cfg["hold_s"]
        )
        await driver.close()
        for cell in scale["cells"]:
            cell["table"] = "6-direct"  # not the paper's portal path: kept out of Table 6
        series = _scale_series(scale["points"], "direct", "exp4_direct.png")
        return result(
            "Experiment 4 baseline: start/stop with 1..N robots, direct publish",
            series=[series],
            notes=[f"odometry watched on at most {ODOM_WATCH_MAX} robots per trial"],
            **scale,
        )

    async def exp4_portal(self) -> dict:
        """Experiment 4 through the portal: teleop and stop over /ws/fleet/ for 1, 2, 4 ... N robots (Table 6)."""
        links = await self.links(self.fleet_names(max(self.cfg["counts"])))
        driver = await self.portal_driver(links)
        counts = [n for n in self.cfg["counts"] if n <= len(links)]
        try:
            scale = await robots_scale(
                driver, links, self.watches, self.reception, counts, self.cfg["repeats"], self.cfg["hold_s"]
            )
        finally:
            await driver.close()
        series = _scale_series(scale["points"], "portal", "exp4_portal.png")
        return result(
            "Experiment 4: start/stop with 1..N robots through the portal's WebSocket (Table 6)",
            series=[series],
            notes=[
                f"odometry watched on at most {ODOM_WATCH_MAX} robots per trial",
                "robots registered by hand (no identification); teleop/stop commands over /ws/fleet/",
            ],
            **scale,
        )

    async def latency(self) -> dict:
        links = await self.links(self.fleet_names(max(self.cfg["latency"])), watch=0)
        direct = DirectDriver(self.clients)
        measured = await command_latency(
            direct, links, self.reception, self.cfg["latency"], self.cfg["rounds"]
        )
        await direct.close()
        out = result(
            "Command latency: issued -> received at the robot's endpoint (direct and portal)",
            direct=measured["detail"],
            summary={"direct_latency_ms": measured["summary"]},
        )
        try:
            portal_driver = await self.portal_driver(links)
            via_portal = await command_latency(
                portal_driver, links, self.reception, self.cfg["latency"], self.cfg["rounds"]
            )
            await portal_driver.close()
        except Exception as exc:  # the direct half stands on its own
            out["status"], out["reason"] = "partial", f"portal path not measured: {type(exc).__name__}: {exc}"
            return out
        out["portal"] = via_portal["detail"]
        out["summary"]["command_latency_ms"] = via_portal["summary"]
        try:
            per_call, out["profile"] = await asyncio.to_thread(
                profile_teleop, links[0].name, self.portal.user
            )
        except Exception as exc:  # the profile explains; it is not a measurement
            per_call, out["profile"] = None, f"teleop profile failed: {type(exc).__name__}: {exc}"
        out["missed"] = latency_why(via_portal["summary"], per_call)
        out["ratio_p50"] = {
            n: _ratio(via_portal["summary"][n]["p50"], measured["summary"][n]["p50"])
            for n in via_portal["summary"]
        }
        try:
            via_relay = await self.relayed_latency(links)
        except Exception as exc:  # the floor explains the portal's figure; it is not the measurement
            out["relay"] = f"relay not measured: {type(exc).__name__}: {exc}"
            return out
        out["relay"] = via_relay["detail"]
        out["summary"]["relay_latency_ms"] = via_relay["summary"]
        out[
            "relay_ratio_p50"
        ] = {  # any process in between, with the portal's libraries, over the direct path
            n: _ratio(via_relay["summary"][n]["p50"], measured["summary"][n]["p50"])
            for n in via_relay["summary"]
        }
        out["portal_over_relay_p50"] = {  # what the portal adds to that floor
            n: _ratio(via_portal["summary"][n]["p50"], via_relay["summary"][n]["p50"])
            for n in via_relay["summary"]
        }
        return out

    async def relayed_latency(self, links) -> dict:
        """The command latency through a bare relay (bench.relay): the floor under the portal's hop."""
        with relay.Relay(free_port(), os.path.join(tempfile.gettempdir(), "fleet-bench-relay.log")) as served:
            ws = await websockets.connect(served.url, max_size=None, ping_interval=None)
            driver = relay.RelayDriver(ws, links)
            try:
                return await command_latency(
                    driver, links, self.reception, self.cfg["latency"], self.cfg["rounds"]
                )
            finally:
                await driver.close()

    async def portal_driver(self, links) -> PortalDriver:
        """The portal's teleop over /ws/fleet/, robots registered by hand (no identification)."""
        ids = await asyncio.to_thread(hand_register, links)
        self.portal.start_web()
        self.portal.start_worker()
        cookie = await asyncio.to_thread(self.portal.session_cookie)
        ws = await websockets.connect(
            f"{self.portal.ws_url}/ws/fleet/",
            max_size=None,
            ping_interval=None,  # the bench measures; a keepalive timeout must not end a run
            additional_headers={"Cookie": f"sessionid={cookie}", "Origin": self.portal.http_url},
        )
        return PortalDriver(ws, ids)

    async def portal_grid(self, table: int, identified: bool) -> dict:
        (link,) = await self.links(["turtlebot"])
        if identified:
            await asyncio.to_thread(auto_register, [self.sim.urls["turtlebot"]])
        driver = await self.portal_driver([link])
        grid = await speed_grid(
            driver, link, self.watches, self.reception, self.cfg["repeats"], self.cfg["hold_s"], table=table
        )
        await driver.close()
        return result(
            f"Experiment {table - 2}: through the portal, "
            + ("robot registered and identified by the portal" if identified else "robot registered by hand"),
            cells=grid.pop("cells"),
            notes=[grid["cap"]],
            **grid,
        )

    async def staleness(self) -> dict:
        n = self.cfg["stale_robots"]
        links = await self.links(self.fleet_names(n), watch=0)
        if len(links) < n:
            raise Unavailable(f"only {len(links)} simulated robots (wanted {n})")
        await asyncio.to_thread(hand_register, links)
        self.portal.start_web()
        feeder = subprocess.Popen(
            [sys.executable, "-m", "bench.live_staleness", "feed"],
            cwd=RESULTS.parent.parent,
            env={**os.environ, **self.portal.env},
        )
        driver = DirectDriver(self.clients)
        try:
            await driver.start(links, links[0].max_linear * 0.3, 0.3)
            cookie = await asyncio.to_thread(self.portal.session_cookie)
            await asyncio.sleep(2.0)
            got = await measure(
                f"{self.portal.ws_url}/ws/fleet/", cookie, self.portal.http_url, 10, self.cfg["stale_s"]
            )
        finally:
            await driver.stop(links)
            await driver.close()
            feeder.terminate()
            feeder.wait(timeout=10)
        stats = got["staleness_ms"]
        if not stats["n"]:
            raise Unavailable(
                f"no pose reached the browsers ({got['errors'][:2] or 'no fleet.poses messages'})"
            )
        return result(
            "Live staleness: simulator odometry -> browser WebSocket",
            **got,
            summary={
                "live_staleness_ms": {"p50": stats["p50"], "p99": stats["p99"], "robots": n, "clients": 10}
            },
        )

    def plan(self) -> list[tuple[str, str, object]]:
        """Every experiment in run order: (name, title, coroutine function)."""
        plan = [
            ("exp1_direct", "direct publish, Table 3", self.exp1_direct),
            ("exp2_portal", "portal, hand-registered, Table 4", lambda: self.portal_grid(4, False)),
            ("exp3_portal_identified", "portal, identified, Table 5", lambda: self.portal_grid(5, True)),
            ("exp4_scale_direct", "1..N robots, direct", self.exp4_scale_direct),
            ("latency", "command latency portal vs direct", self.latency),
        ]
        plan.append(("exp4_portal", "1..N robots through the portal, Table 6", self.exp4_portal))
        plan.append(("live_staleness", "live push staleness", self.staleness))
        return plan

    def exec_plan(self) -> list[tuple[str, str, object]]:
        """The execution experiments: run on their own world once the big one is stopped."""
        names = ("exp5_move", "exp6_sequence", "stop_queued", "exp7_success", "typed_stop")
        return [(name, name, lambda n=name: self.needs_execution(n)) for name in names]

    async def run_all(self, only: set[str] | None = None, plan=None) -> None:
        for name, title, make in plan or self.plan():
            if not only or name in only:
                await self.guarded(name, title, make())
        for client in self.clients.values():
            await client.close()
        self.clients.clear()

    EXEC_ENDPOINTS = ("robots", "turtlebot", "husky", "tiago", "extra")
    EXEC_EXTRA = 3  # robot5..robot7, parked in the corner room 3, registered by typed_stop only
    EXEC_ROBOTS = ("robot1", "robot2", "robot3", "robot4", "turtlebot", "husky", "tiago")

    def exec_link(self, name: str):
        return sim_robot_link(self.exec_sim, name)

    def exec_links(self, n: int) -> list:
        return [self.exec_link(f"robot{i}") for i in range(1, n + 1)]

    async def needs_execution(self, name: str) -> dict:
        """Run an execution experiment on its own small world (the paper's robots, maybe faster than real)."""
        if self.exec_sim is None:
            self.exec_sim = self.stack.enter_context(
                running_world(
                    "paper", extra=self.EXEC_EXTRA, endpoints=self.EXEC_ENDPOINTS, time_scale=self.time_scale
                )
            )
            links = [self.exec_link(n) for n in self.EXEC_ROBOTS]
            await asyncio.to_thread(hand_register, links)
        self.portal.start_web()
        self.portal.start_worker()
        self.portal.start_links()  # live poses: the engine routes around robots parked on the way
        limit = self.cfg.get(f"{name}_limit_s", self.cfg["exec_limit_s"])
        try:
            return await asyncio.wait_for(execution.run(self, name), limit)
        except TimeoutError:
            tail = self.portal.log_tail("executor", 400)
            raise RuntimeError(f"did not finish within {limit} s; executor log ends: {tail}") from None


def profile_teleop(name: str, user, calls: int = 200) -> tuple[float, str]:
    """cProfile a press's checks (execution.control.teleop_grant), what the portal runs once per press."""
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from execution.control import teleop_grant

    per_call, body = profile_calls(lambda: teleop_grant(name, user), calls)
    return (
        per_call,
        f"execution.control.teleop_grant, {calls} calls: {per_call:.2f} ms per call (under cProfile)\n{body}",
    )


def latency_why(portal: dict, per_call_ms: float | None) -> str:
    """Why the portal's command latency misses its goals, if it does."""
    one, hundred = portal.get("1", {}).get("p99"), portal.get("100", {}).get("p99")
    if (one is None or one <= 20) and (hundred is None or hundred <= 50):
        return ""
    cost = f"{per_call_ms:.1f} ms" if per_call_ms is not None else "several ms"
    return (
        f"command p99 {one} ms with 1 robot, {hundred} ms with 100 moving. A press is checked once in a thread "
        f"(robot, role and lease, running instruction, move topic: about {cost}, profile below); its repeats are "
        "published from the web process's event loop on its own rosbridge links, without thread or database "
        "(fleet/held_teleop.py), the grants re-checked in one batched query every 0.5 s. What remains is the "
        "per-message work of one ASGI process (frame and JSON decode, channels dispatch, the publish, the reply) "
        "on a 2-core machine that also runs the 200-robot simulator and the bench, and pauses of that process "
        "(a garbage collection, a burst of first presses checked in threads). Several ASGI processes (docs/scale.md) "
        "or one socket per operator spread the load."
    )


def _ratio(a, b):
    return round(a / b, 2) if a is not None and b else None


def _scale_series(points: list[dict], label: str, file: str) -> dict:
    return {
        "title": f"Start/stop response vs robots ({label})",
        "x": "robots",
        "y": "seconds (median)",
        "file": file,
        "logx": True,
        "lines": {
            "start": [(p["robots"], p["start_s"]["p50"]) for p in points],
            "stop": [(p["robots"], p["stop_s"]["p50"]) for p in points],
        },
    }


def auto_register(urls: list[str]):
    # Deferred: needs the app registry (bench modules are imported before django.setup()).
    from robots.registration import register_endpoints

    return register_endpoints(urls)


def run_components(mode: str, timeout: int, env: dict, out_dir: Path) -> dict[str, dict]:
    """The component benches: run each as `python -m bench.<name> --<mode> --out <out_dir>`."""
    out = {}
    for name, (filename, keys) in COMPONENTS.items():
        title = f"component bench bench/{name}.py"
        timeout = COMPONENT_TIMEOUTS.get(name, {}).get(mode, timeout)
        print(f"[bench] {name} ...", flush=True)
        try:
            proc = subprocess.run(
                [sys.executable, "-m", f"bench.{name}", f"--{mode}", "--out", str(out_dir)],
                cwd=RESULTS.parent.parent,
                capture_output=True,
                env={**os.environ, **env},
                text=True,
                timeout=timeout,
            )
        except subprocess.TimeoutExpired:
            out[f"component_{name}"] = result(title, "error", reason=f"did not finish within {timeout} s")
            continue
        out[f"component_{name}"] = _component_result(out_dir / filename, title, keys, proc)
    return out


def _component_result(path: Path, title: str, keys, proc) -> dict:
    if proc.returncode != 0 or not path.exists():
        return result(title, "error", reason=f"exit {proc.returncode}: {(proc.stderr or proc.stdout)[-800:]}")
    data = json.loads(path.read_text())
    summary = {k: data[k] for k in keys if k in data}
    status = "ok" if summary else "partial"
    reason = "" if summary else f"its JSON has none of the summary keys {keys}"
    return result(
        title, status, reason=reason, summary=summary, component=data, profile=data.get("profile", "")
    )


async def bench_async(mode: str, portal, only: set[str] | None = None) -> dict:
    with running_world("paper", extra=MODES[mode]["extra"]) as sim:
        bench = Bench(mode, sim, portal)
        await bench.run_all(only)
    # the big world is stopped: its physics no longer takes CPU from the execution experiments' own world
    with bench.stack:
        await bench.run_all(only, bench.exec_plan())
    return bench.results


def run_fleet(
    mode: str,
    out_dir: Path = RESULTS,
    no_components: bool = False,
    only: set[str] | None = None,
    keep: bool = False,
) -> dict:
    """Set the private portal up (synchronously: Django's ORM refuses an event loop), then run the bench."""
    portal = Portal()
    try:
        portal.setup()
        timeout = MODES[mode]["component_timeout"]
        results = {} if no_components else run_components(mode, timeout, portal.env, out_dir)
        return results | asyncio.run(bench_async(mode, portal, only))
    finally:
        portal.close(keep=keep)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_const", const="quick", dest="mode")
    group.add_argument("--full", action="store_const", const="full", dest="mode")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument(
        "--no-components", action="store_true", help="skip the component benches (for a re-run)"
    )
    parser.add_argument("--only", default="", help="comma-separated experiment names (a debugging re-run)")
    parser.add_argument("--keep", action="store_true", help="keep the portal's temp dir (its logs)")
    args = parser.parse_args(argv)
    mode = args.mode or "full"
    started = time.time()
    only = {n for n in args.only.split(",") if n} or None
    if only and args.out == RESULTS:
        args.out = Path(tempfile.mkdtemp(prefix="bench-only-"))  # a partial run never replaces the results
    results = run_fleet(mode, args.out, args.no_components or bool(only), only, args.keep)
    meta = {"mode": mode, "seconds": round(time.time() - started), "at": time.strftime("%Y-%m-%d %H:%M:%S")}
    summary = report.write_all(results, args.out, mode, meta)
    print(report.render_headline(summary))
    print(f"[bench] wrote {args.out}/summary.json and REPORT.md in {meta['seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
