"""The fleet across hosts (issue 19): figures from a cluster of network namespaces on this machine.

    sudo .venv/bin/python -m bench.cluster --robots 100 [--clients 50] [--rounds 10]
    sudo .venv/bin/python -m bench.cluster --report        (summary.json, REPORT.md, cost_curve.png again)

Brings up deploy/cluster.py's cluster with --robots split over its two simulator shards, then, from the machine
itself (the bridge's 10.77.0.1), measures what issue 19 sets goals for:

- registration_s: both shards' endpoints registered in bulk through web1's API (POST /api/robots/register,
  queued, run by a control worker) until both records are finished; online_s until the links host has every
  robot online.
- commands: every robot turned by teleop over the dashboard's socket (/ws/fleet/, alternately on web1 and web2),
  `rounds` times, all robots moving; latency = the command sent -> the same command (its angular speed) seen on the
  robot's cmd_vel at its shard (subscribed over the shard's rosbridge, so one relay hop more than the robot has).
  Counted at the end of the run: a command seen after its round's ROUND_WAIT_S is `late`, one never seen `missing`.
- stop-all: the dashboard's STOP ({"command": "stop"} with every robot) while all turn -> the first zero Twist at
  each robot; p99 over robots and the time to the last robot, per trial.
- live: `clients` browser-like WebSocket clients (logged in by cookie, half on each web host) reading
  fleet.poses while every robot turns: robots each client saw, the pose rate per robot per client (Hz), and the
  staleness of each pose (received - when the links process took its odometry; one clock, one machine): of the
  teleop (the rounds and the stop trials) as `staleness_ms`, under the instructions the window reaches into as
  `staleness_ms_under_instructions`, and by phase (`staleness_ms_by_phase`).
- cpu: CPU seconds per wall second of every process of each host during the measurements, and per robot.

Each size writes size-N.json under bench/results/cluster/; summary.json, REPORT.md and cost_curve.png are made
from all the sizes there. The client processes share the machine's cores with the cluster, so every figure
includes the load the measuring adds; the machine's load average at the start is recorded with them.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing
import os
import re
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import psutil
import websockets

from bench import frames
from bench import report as report_file
from deploy.cluster import Cluster, down, host_pids, reason_unavailable
from deploy.cluster_client import Odometry, Portal
from experiments.stats import summarize
from portal.fanout import decode

ROUND_WAIT_S = 5.0  # a round's commands not all seen by then: the next round goes (those are late, not lost)
STOP_WAIT_S = 5.0  # a stop trial's zeros not all seen by then: the next trial goes (those are late, not lost)
STOP_PHASE_S = 0.5  # staleness after a stop-all is told apart in steps of this (by_phase)
INSTRUCTIONS_PHASE = "instructions (after the stop trials)"
# Robots per cmd_vel link of the reception. A simulator queues at most SEND_QUEUE (1,000) messages for one client
# and drops the oldest beyond (logged): one link for a shard's 500 robots could lose some of a burst's commands.
RECEPTION_CHUNK = 100
DECODED = 5  # dashboards that decode every pose (robots seen, staleness); the rest count poses per batch
FRAME_TYPE = re.compile(
    r'\{"type":"([^"]+)"'
)  # a page frame's type, as portal.consumers writes it (first key)
INSTRUCTION_CHUNK = 50  # robots per instruction when every robot is instructed (a page's selection)
ODOMETRY_MS = 1000  # the instructed phase's odometry watch, per robot (throttled at the shards)
SAID_WITHIN_DEG = 5.0  # an outcome's degrees this near the shard's odometry (1 Hz, read at rest) are true
TURN_TOLERANCE_DEG = 10.0  # a robot told to turn 90 degrees that turned 80 to 100 did it
SETTLE_WAIT_S = 120.0  # an instructed phase's instructions not final by then: reported as they are
FINAL = {"succeeded", "failed", "cancelled", "refused", "answered"}
LIVE_S = 12.0  # seconds the dashboards read poses, while every robot turns
OUT = Path(__file__).resolve().parent / "results" / "cluster"
GOALS = {  # issue 19, for 1,000 robots
    "registration_s": 10.0,
    "live_hz": 5.0,
    "staleness_p99_ms": 150.0,
    "command_p99_ms": 50.0,
    "stop_all_p99_ms": 100.0,
}


def host_cpu(host: str) -> float:
    """CPU seconds used so far by every process of one host (the namespace's processes)."""
    total = 0.0
    for pid in host_pids(host):
        try:
            times = psutil.Process(pid).cpu_times()
            total += times.user + times.system
        except psutil.Error:
            pass
    return total


def cpu_seconds() -> dict[str, float]:
    """CPU seconds used so far by every process of each host."""
    return {
        host: host_cpu(host) for host in ("db", "web1", "web2", "exec1", "exec2", "sim1", "sim2", "links")
    }


class Reception:
    """Every Twist each robot's cmd_vel carried, with the time it reached us, from the shards' rosbridge.

    Runs in a process of its own (`start`), so that neither the bench's commanders nor the dashboards' frames keep
    it from reading: a simulator cuts off a client that stops reading for simworker.connection.STALL_SECONDS, and
    every command after that would be unseen, not lost. A link that drops anyway is reconnected and resubscribed;
    the time without a link is kept (`gaps`) and reported with the figures, so an unseen command is told apart
    from a missing one. The bench asks it over a pipe: first(name, since, angular) for many robots in one call."""

    def __init__(self, shards: dict[str, list[str]]) -> None:
        self.shards = shards
        self.times: dict[str, list[tuple[float, float]]] = defaultdict(list)  # name -> (t, angular z)
        self.gaps: list[dict] = []  # {"shard", "lost_at", "back_at"}: time with no link to a shard
        self._process = None
        self._pipe = None

    # the bench's side
    def start(self) -> None:
        """The process, subscribed to every robot's cmd_vel (waits until it says so)."""
        self._pipe, theirs = multiprocessing.Pipe()
        self._process = multiprocessing.get_context("spawn").Process(
            target=_receive, args=(self.shards, theirs), name="reception", daemon=True
        )
        self._process.start()
        if not self._pipe.poll(60) or self._pipe.recv() != "ready":
            raise RuntimeError("bench.cluster: the cmd_vel reception did not subscribe within 60 s")

    async def first_of(
        self, since: dict[str, float], angular: float | None, until: float = math.inf
    ) -> dict[str, float | None]:
        """For each robot, when the first Twist with this angular speed (None: any but zero) since its time (and
        before until) was seen (None: not seen)."""
        return await asyncio.to_thread(self._ask, ("first", since, angular, until))

    async def stop(self) -> list[dict]:
        """End the process; the link gaps it had."""
        gaps = await asyncio.to_thread(self._ask, ("stop",))
        await asyncio.to_thread(self._process.join, 10)
        return gaps

    def _ask(self, request: tuple):
        self._pipe.send(request)
        return self._pipe.recv()

    # the process's side
    def first(self, name: str, since: float, angular: float | None, until: float = math.inf) -> float | None:
        """angular None: any turning Twist (an executor's, whose speeds are its own)."""
        for t, z in self.times.get(name, ()):
            if since <= t < until and (abs(z) > 1e-6 if angular is None else abs(z - angular) < 1e-6):
                return t
        return None

    async def serve(self, pipe) -> None:
        stop = asyncio.Event()
        parts = [  # a link per RECEPTION_CHUNK robots: a burst of a whole shard's commands fits each one's queue
            (url, names[i : i + RECEPTION_CHUNK])
            for url, names in self.shards.items()
            for i in range(0, len(names), RECEPTION_CHUNK)
        ]
        subscribed = [asyncio.Event() for _ in parts]
        links = [
            asyncio.create_task(self._follow(url, names, stop, ready))
            for (url, names), ready in zip(parts, subscribed, strict=True)
        ]
        await asyncio.wait_for(asyncio.gather(*(ready.wait() for ready in subscribed)), 60)
        pipe.send("ready")
        while True:
            request = await asyncio.to_thread(pipe.recv)
            if request[0] == "stop":
                stop.set()
                await asyncio.gather(*links, return_exceptions=True)
                pipe.send(self.gaps)
                return
            _, since, angular, until = request
            pipe.send({name: self.first(name, t0, angular, until) for name, t0 in since.items()})

    async def _follow(self, url: str, names: list[str], stop: asyncio.Event, ready: asyncio.Event) -> None:
        lost_at = None
        while not stop.is_set():
            try:
                async with websockets.connect(url, max_size=None, open_timeout=10) as ws:
                    for name in names:
                        message = {
                            "op": "subscribe",
                            "topic": f"/{name}/cmd_vel",
                            "type": "geometry_msgs/Twist",
                        }
                        await ws.send(json.dumps(message))
                    ready.set()
                    if lost_at is not None:
                        self.gaps.append({"shard": url, "lost_at": lost_at, "back_at": time.time()})
                        lost_at = None
                    async for now, raw in frames.until(ws, stop):
                        message = json.loads(raw)
                        if message.get("op") == "publish":
                            name = message["topic"].split("/")[1]
                            self.times[name].append((now, float(message["msg"]["angular"]["z"])))
            except (OSError, websockets.ConnectionClosed, TimeoutError) as error:
                if lost_at is None:
                    lost_at = time.time()
                    print(f"bench.cluster: cmd_vel reception lost {url}: {error!r}; reconnecting", flush=True)
                await asyncio.sleep(0.2)
        if lost_at is not None:
            self.gaps.append({"shard": url, "lost_at": lost_at, "back_at": None})


def _receive(shards: dict[str, list[str]], pipe) -> None:
    asyncio.run(Reception(shards).serve(pipe))


async def connect(url: str, cookie: str):
    ws_url = url.replace("http://", "ws://") + "ws/fleet/"
    origin = url.rstrip("/")
    return await websockets.connect(
        ws_url, additional_headers={"Cookie": f"sessionid={cookie}", "Origin": origin}, max_size=None
    )


async def browser(
    url: str, cookie: str, seen: dict, stale: list[tuple[float, float]] | None, live: dict
) -> None:
    """One dashboard: every fleet.poses batch it is pushed while live["on"], counted per robot, with each pose's
    staleness (when it came, how old it was in ms); live["connected"] counts the dashboards connected so far.

    Only the dashboards given `stale` read every pose (robots seen, staleness); the others count the rows of each
    batch without making poses of them (seen["poses"], seen["batches"]): the server does the same work for every
    socket, and one client process could not decode 50 sockets' worth of poses on this machine."""
    async with await connect(url, cookie) as ws:
        live["connected"] += 1
        async for now, raw in frames.until(ws, live["stop"]):
            if not live["on"]:
                continue
            live["frames"] += 1  # every frame a dashboard is sent: each one a socket write for the web
            kind = FRAME_TYPE.match(raw)
            live["kinds"][kind.group(1) if kind else "?"] += 1
            if '"fleet.poses"' not in raw:
                continue
            if (
                stale is None
            ):  # the rows of the tick counted, not parsed (portal.fanout.encode's "],[" between rows)
                seen["batches"] += 1
                seen["poses"] += raw.count("],[") + 1 if '"rows":[[' in raw else 0
                continue
            for pose in decode(json.loads(raw)):
                seen[pose["id"]] += 1
                if pose.get("t"):
                    stale.append((now, (now - pose["t"]) * 1000))


def browsers(webs: list[str], cookie: str, clients: int, robots: int, seconds: float, pipe) -> None:
    """`clients` dashboards, in a process of their own (so that reading every pose does not delay the timing of
    commands): says when all are connected, reads for `seconds`, then sends back robots seen, pose rate and
    staleness per client, and connection errors."""

    async def main() -> dict:
        live = {"stop": asyncio.Event(), "on": False, "connected": 0, "frames": 0, "kinds": Counter()}
        seen = [defaultdict(int) for _ in range(clients)]
        stale: list[tuple[float, float]] = []
        start = time.monotonic()
        tasks = [
            asyncio.create_task(browser(webs[i % 2], cookie, seen[i], stale if i < DECODED else None, live))
            for i in range(clients)
        ]
        while (
            live["connected"] < clients
            and time.monotonic() - start < 120
            and not all(t.done() for t in tasks)
        ):
            await asyncio.sleep(0.1)
        connect_s = time.monotonic() - start
        await asyncio.sleep(1.0)  # past the snapshots
        pipe.send({"connected": live["connected"]})
        live["on"], began = True, time.monotonic()
        await asyncio.sleep(seconds)
        live["on"], took = False, time.monotonic() - began
        live["stop"].set()
        done = await asyncio.gather(*tasks, return_exceptions=True)
        return {
            "clients": clients,
            "clients_that_saw_poses": sum(1 for s in seen if s),
            "decoded_clients": min(DECODED, clients),
            "all_connected_s": round(connect_s, 1),
            "seconds": round(took, 1),
            "errors": [repr(d) for d in done if isinstance(d, BaseException)][:5],
            "failed_clients": sum(isinstance(d, BaseException) for d in done),
            "robots_seen_per_client": summarize([len(s) for s in seen[:DECODED]]),
            "hz_per_robot_per_client": summarize(
                [sum(s.values()) / len(s) / took for s in seen[:DECODED] if s]
                + [s["poses"] / max(1, robots) / took for s in seen[DECODED:]]
            ),
            "batches_per_s_per_client": summarize([s["batches"] / took for s in seen[DECODED:]]),
            "frames_per_s_per_client": round(live["frames"] / took / clients, 2),
            "frames_by_type": dict(live["kinds"].most_common()),  # a batch frame is one, whatever it holds
            "staleness_samples": stale,  # (when, ms): measure() splits them by what the bench was doing
        }

    pipe.send(asyncio.run(main()))
    pipe.close()


async def drain(ws) -> None:
    async for _ in ws:
        pass


async def measure(cluster: Cluster, portal: Portal, ids: dict[str, int], clients: int, rounds: int) -> dict:
    shards = {cluster.sim_url(h): cluster.shard_robots(h) for h in ("sim1", "sim2")}
    cookie = portal.session.cookies.get("sessionid")
    webs = [cluster.url("web1"), cluster.url("web2")]
    reception = Reception(shards)
    await asyncio.to_thread(reception.start)
    commanders = [await connect(web, cookie) for web in webs]
    drains = [asyncio.create_task(drain(ws)) for ws in commanders]
    names = sorted(ids)

    async def turn_all(angular: float) -> dict[str, float]:
        sent = {}
        for index, name in enumerate(names):
            message = {"command": "teleop", "robot": ids[name], "linear": 0.0, "angular": angular}
            sent[name] = time.time()
            await commanders[index % 2].send(json.dumps(message))
        return sent

    await turn_all(0.0)  # warm-up: each web host's links and checks for every robot
    await asyncio.sleep(2)
    results, pipe = multiprocessing.Pipe()
    dashboards = multiprocessing.get_context("spawn").Process(
        target=browsers, args=(webs, cookie, clients, len(ids), LIVE_S, pipe), name="dashboards"
    )
    dashboards.start()
    # the dashboards connected and given their snapshot before the robots turn
    ready = await asyncio.to_thread(results.recv) if await asyncio.to_thread(results.poll, 150) else {}
    print(f"bench.cluster: dashboards connected: {ready}", flush=True)
    cpu_before, wall_before = cpu_seconds(), time.monotonic()
    turns = []  # (angular, {name: sent at}) of each round
    for round_ in range(rounds):
        angular = round(0.3 + 0.01 * round_, 3)
        sent = await turn_all(angular)
        turns.append((angular, sent))
        deadline = time.monotonic() + ROUND_WAIT_S  # the next round goes then, whatever has arrived
        while time.monotonic() < deadline:
            await asyncio.sleep(0.25)
            if all((await reception.first_of(sent, angular)).values()):
                break
        await asyncio.sleep(0.25)
    stops, stops_began = [], time.time()  # when each trial's stop was sent
    for _ in range(3):
        await turn_all(0.5)
        await asyncio.sleep(1.0)
        stops.append(t0 := time.time())
        await commanders[0].send(json.dumps({"command": "stop", "robots": [ids[n] for n in names]}))
        since = dict.fromkeys(names, t0)
        deadline = time.monotonic() + STOP_WAIT_S
        while time.monotonic() < deadline and not all((await reception.first_of(since, 0.0)).values()):
            await asyncio.sleep(0.25)
    cpu_after, wall = cpu_seconds(), time.monotonic() - wall_before
    stops_ended = time.time()  # the instructions come next (the dashboards may still be reading)
    # Each trial's zeros as seen by the end of the run, as the commands are: a zero seen after the trial's
    # STOP_WAIT_S is late, one never seen (before the next trial's stop) missing.
    stop_trials = []
    for t0, until in zip(stops, [*stops[1:], math.inf], strict=True):
        each = await reception.first_of(dict.fromkeys(names, t0), 0.0, until)
        got = [(t - t0) * 1000 for t in each.values() if t is not None]
        missed = sorted(name for name, t in each.items() if t is None)
        late = sum(ms > STOP_WAIT_S * 1000 for ms in got)
        stop_trials.append(
            {
                **summarize(got),
                "late": late,
                "missing": len(missed),
                "missed_robots": missed[:50],
                "sent_at": t0,
            }
        )
    # Each round's commands as seen by the end of the run (its stop trials too): a command later than its round is
    # late, not lost; one never seen is missing. Every round's angular speed is its own, so none is taken for
    # another's.
    latencies, missing = [], 0
    for angular, sent in turns:
        for name, got in (await reception.first_of(sent, angular)).items():
            if got is None:
                missing += 1
            else:
                latencies.append((got - sent[name]) * 1000)
    late = sum(ms > ROUND_WAIT_S * 1000 for ms in latencies)
    under_instructions = await instructed(cluster, portal, reception, ids, commanders[0])
    gaps = await reception.stop()
    live = await asyncio.to_thread(results.recv) if await asyncio.to_thread(results.poll, 60) else {}
    # The dashboards read for LIVE_S from before the first round: at a few hundred robots and more that reaches
    # past the stop trials into the instructions. "staleness_ms" is the teleop's (the rounds and the stop trials,
    # every robot turning on commands, as in the runs of 2026-11-24); the instructions' is said beside it.
    samples = live.pop("staleness_samples", [])
    live["staleness_ms"] = summarize([ms for at, ms in samples if at < stops_ended])
    live["staleness_ms_under_instructions"] = summarize([ms for at, ms in samples if at >= stops_ended])
    live["staleness_ms_by_phase"] = by_phase(samples, stops_began, stops, stops_ended)
    dashboards.join(10)
    for task in drains:
        task.cancel()
    for ws in commanders:
        await ws.close()
    cpu = {host: round((cpu_after[host] - cpu_before.get(host, 0.0)) / wall, 3) for host in cpu_after}
    stop_each = [trial["max"] for trial in stop_trials if trial["max"] is not None]
    return {
        "commands": {**summarize(latencies), "missing": missing, "late": late, "rounds": rounds},
        "reception_gaps": gaps,  # time the bench's cmd_vel watcher had no link to a shard (its commands unseen)
        "stop_all_ms": {
            "trials": stop_trials,
            "p99_over_robots": max((t["p99"] for t in stop_trials if t["p99"] is not None), default=None),
            "to_last_robot_max": max(stop_each, default=None),
        },
        "live": live,
        "instructions": under_instructions,
        "cpu_cores": {**cpu, "total": round(sum(cpu.values()), 3)},
        # what the CPU window held: per press and per robot stopped is the cost model's "doing" (docs/scale.md)
        "cpu_window": {
            "seconds": round(wall, 2),
            "presses": len(names) * (rounds + 3),
            "robots_stopped": 3 * len(names),
        },
    }


def by_phase(
    samples: list[tuple[float, float]], stops_began: float, stops: list[float], stops_ended: float
) -> dict:
    """Staleness while the rounds of commands went, in the stop trials by the time since the last stop-all was
    sent (half-second steps; STOP_PHASE_S), and once the instructions began (LIVE_S may reach into them): where
    a tail of staleness comes from."""
    phases: dict[str, list[float]] = defaultdict(list)
    for at, ms in samples:
        last = max((t0 for t0 in stops if t0 <= at), default=None)
        if at < stops_began:
            phases["rounds"].append(ms)
        elif at >= stops_ended:
            phases[INSTRUCTIONS_PHASE].append(ms)
        elif last is None:
            phases["stop trials, before the first stop-all"].append(ms)
        else:
            step = math.floor((at - last) / STOP_PHASE_S) * STOP_PHASE_S
            phases[f"{step:.1f}-{step + STOP_PHASE_S:.1f} s after a stop-all"].append(ms)
    return {phase: summarize(phases[phase]) for phase in sorted(phases, key=_phase_order)}


def _phase_order(phase: str) -> float:
    first = {"rounds": -2.0, "stop trials, before the first stop-all": -1.0, INSTRUCTIONS_PHASE: math.inf}
    return first.get(phase) or float(phase.split("-")[0])


async def instructed(cluster: Cluster, portal: Portal, reception: Reception, ids: dict[str, int], ws) -> dict:
    """Every robot moved under instructions (not teleop), then stopped mid-instruction (issue 35, deliver 4).

    turn: "turn left 90 degrees" to every robot (INSTRUCTION_CHUNK robots per instruction, through the API as a
    page's selection sends it); started = the instruction posted -> the robot's executor's first turning Twist at
    its shard; settled = every instruction final; turned = the robots whose own odometry (at the shard) turned
    90 +- TURN_TOLERANCE_DEG. stop: "turn left 720 degrees" to every robot, the dashboard's STOP once most turn
    -> the first zero Twist at each robot, every instruction final, every robot's odometry at rest."""
    names = sorted(ids)
    shards = {cluster.sim_url(h): cluster.shard_robots(h) for h in ("sim1", "sim2")}
    with Odometry(shards, period_ms=ODOMETRY_MS) as odometry:
        await asyncio.to_thread(portal.post, "instructions", {"text": "release all robots"})
        await wait_until(lambda: odometry.at_rest(names, within=3 * ODOMETRY_MS / 1000), 30)
        before = {name: odometry.motion[name].yaw for name in names}
        turn, sent = await instruct(portal, "turn left 90 degrees", ids)
        settled = await settle(portal, turn["ids"])
        started = await reception.first_of(sent, None)
        await asyncio.sleep(3 * ODOMETRY_MS / 1000)  # the last odometry of every robot, at rest
        turned = {name: math.degrees(wrapped(odometry.motion[name].yaw - before[name])) for name in names}
        said, failures = await said_turns(portal, turn["ids"])
        turn.update(
            started_ms=summarize([(t - sent[name]) * 1000 for name, t in started.items() if t is not None]),
            not_started=sorted(name for name, t in started.items() if t is None)[:50],
            **settled,
            turned_deg=summarize(list(turned.values())),
            turned_ok=sum(abs(d - 90) <= TURN_TOLERANCE_DEG for d in turned.values()),
            turned_off=sorted(name for name, d in turned.items() if abs(d - 90) > TURN_TOLERANCE_DEG)[:50],
            # the outcome's words against the shard's odometry: a robot said to have turned what it turned
            said_true=sum(abs(said[n] - turned[n]) <= SAID_WITHIN_DEG for n in names if n in said),
            said_false=sorted(n for n in names if n in said and abs(said[n] - turned[n]) > SAID_WITHIN_DEG)[
                :50
            ],
            said_none=sorted(n for n in names if n not in said)[:50],
            failures=failures,
        )
        print(f"bench.cluster: under instructions: {turn}", flush=True)
        t1 = time.time()
        stop, _ = await instruct(portal, "turn left 720 degrees", ids)
        turning = await wait_until(
            lambda: sum(odometry.motion[n].speed > 0.05 for n in names) >= 0.9 * len(names), 60
        )
        t2 = time.time()
        await ws.send(json.dumps({"command": "stop", "robots": [ids[n] for n in names]}))
        zeros = dict.fromkeys(names)
        deadline = time.monotonic() + STOP_WAIT_S
        while time.monotonic() < deadline and not all(zeros.values()):
            await asyncio.sleep(0.25)
            zeros = await reception.first_of(dict.fromkeys(names, t2), 0.0)
        settled = await settle(portal, stop["ids"])
        _, failures = await said_turns(
            portal, stop["ids"]
        )  # a stop should cancel: what failed instead, and why
        rest = await wait_until(lambda: odometry.at_rest(names, within=3 * ODOMETRY_MS / 1000), 30)
        stop.update(
            turning_s=round(t2 - t1, 2),
            turning_before_stop=turning,
            zeros_ms={
                **summarize([(t - t2) * 1000 for t in zeros.values() if t is not None]),
                "missing": sum(t is None for t in zeros.values()),
            },
            **settled,
            at_rest_s=rest and round(time.time() - t2, 2),
            moving_after=odometry.moving(names)[:50],
            failures=failures,
        )
        print(f"bench.cluster: stopped under instructions: {stop}", flush=True)
    return {"turn": turn, "stop": stop}


async def instruct(portal: Portal, text: str, ids: dict[str, int]) -> tuple[dict, dict[str, float]]:
    """The text to these robots, INSTRUCTION_CHUNK at a time, as a page's selection (POST /api/instructions):
    what was posted (with each POST's time to its answer: post_ms), and when each robot's instruction was sent."""
    names = sorted(ids)
    posted, sent, took = [], {}, []
    for i in range(0, len(names), INSTRUCTION_CHUNK):
        chunk = names[i : i + INSTRUCTION_CHUNK]
        at = time.time()
        body = {"text": text, "robot_ids": [ids[name] for name in chunk]}
        posted.append(await asyncio.to_thread(portal.post, "instructions", body))
        took.append((time.time() - at) * 1000)
        sent.update(dict.fromkeys(chunk, at))
    summary = {
        "text": text,
        "instructions": len(posted),
        "post_ms": summarize(took),
        "ids": [p["id"] for p in posted],
        "at_post": dict(Counter(p["status"] for p in posted)),
        # why, for those the portal refused at once (robot names taken out)
        "refused_because": dict(
            Counter(
                re.sub(r"robot\d+", "robotN", p["outcome"])[:160] for p in posted if p["status"] == "refused"
            )
        ),
    }
    return summary, sent


# one robot's share of an outcome that says the angle it turned: "robot7: succeeded (turned 104° left ...", or a
# failed turn's "robot7: failed (robot7: did not finish within 12 s: turned 60° left (90° left asked))"
SAID_TURN = re.compile(r"(\w+): (?:succeeded|failed) \((?:[^;]*?: )?turned (\d+)° (left|right)")


def said_in(outcome: str) -> dict[str, float]:
    """{robot: the signed degrees the outcome says it turned}, for the robots whose share says it."""
    return {
        name: float(deg) * (1 if side == "left" else -1) for name, deg, side in SAID_TURN.findall(outcome)
    }


async def said_turns(portal: Portal, instruction_ids: list[int]) -> tuple[dict[str, float], dict[str, int]]:
    """{robot: the degrees its instruction's outcome says it turned} (said_in), and the reasons of the robots'
    failures, counted (robot names and angles taken out)."""
    said, failed = {}, Counter()
    for pk in instruction_ids:
        outcome = (await asyncio.to_thread(portal.get, f"instructions/{pk}"))["outcome"]
        said.update(said_in(outcome))
        for reason in re.findall(r"\w+: failed \((.*?)\)(?:; |$)", outcome):
            reason = re.sub(r": turned \d+° .*$", "", re.sub(r"robot\d+", "robotN", reason))
            failed[reason[:160]] += 1
    return said, dict(failed.most_common(5))


async def settle(portal: Portal, instruction_ids: list[int]) -> dict:
    """Wait until every instruction is final (SETTLE_WAIT_S at most): how long, and their statuses then."""
    t0 = time.monotonic()
    while True:
        statuses = [
            (await asyncio.to_thread(portal.get, f"instructions/{pk}"))["status"] for pk in instruction_ids
        ]
        if all(status in FINAL for status in statuses) or time.monotonic() - t0 > SETTLE_WAIT_S:
            break
        await asyncio.sleep(0.5)
    done = all(status in FINAL for status in statuses)
    return {
        "settled_s": round(time.monotonic() - t0, 2) if done else None,
        "statuses": dict(Counter(statuses)),
    }


async def wait_until(condition, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        await asyncio.sleep(0.25)
    return condition()


def wrapped(angle: float) -> float:
    """An angle difference in [-pi, pi) (a robot that turned 90 degrees, whatever its start yaw)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def run_size(robots: int, clients: int, rounds: int, out: Path, keep: bool = False) -> dict:
    # the paper world's own 0.45 m grid fits 532 extra robots; more need a tighter one
    cluster = Cluster(robots_per_shard=robots // 2, spacing=0.3 if robots > 500 else None)
    load = os.getloadavg()
    started = time.monotonic()
    try:
        cluster.up(say=lambda line: print(f"cluster: {line}", flush=True))
        up_s = time.monotonic() - started
        portal = Portal(cluster.url("web1")).login()
        shards = [cluster.sim_url("sim1"), cluster.sim_url("sim2")]
        t0 = time.monotonic()
        records = portal.register(shards, timeout=300)
        registration_s = time.monotonic() - t0
        errors = [record["error"] for record in records if record["error"]]
        registered = sum(len(record["robots"]) for record in records)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            listed = portal.robots()
            if len(listed) == registered and all(r["link_status"] == "online" for r in listed.values()):
                break
            time.sleep(0.5)
        online_s = time.monotonic() - t0
        ids = {name: robot["id"] for name, robot in portal.robots().items()}
        print(f"bench.cluster: {registered} robots registered in {registration_s:.1f} s", flush=True)
        measured = asyncio.run(measure(cluster, portal, ids, clients, rounds))
    finally:
        if not keep:
            down(cluster.root, say=lambda line: print(f"cluster: {line}", flush=True))
    result = {
        "robots": robots,
        "registered": registered,
        "registration_errors": errors,
        "registration_s": round(registration_s, 3),
        "online_s": round(online_s, 3),
        "cluster_up_s": round(up_s, 1),
        "load_average_at_start": [round(x, 2) for x in load],
        "cores": os.cpu_count(),
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        **measured,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / f"size-{robots}.json").write_text(json.dumps(result, indent=1))
    return result


def report(out: Path = OUT) -> dict:
    """summary.json, REPORT.md and cost_curve.png from every size measured."""
    sizes = sorted(
        (json.loads(path.read_text()) for path in out.glob("size-*.json")), key=lambda r: r["robots"]
    )
    summary = {
        "goals_for_1000": GOALS,
        "sizes": {
            str(r["robots"]): {
                "registration_s": r["registration_s"],
                "online_s": r["online_s"],
                "command_ms": {"p50": r["commands"]["p50"], "p99": r["commands"]["p99"]},
                "commands": {  # counted at the end of the run (runs before 2026-11-28 15:00 counted late as missing)
                    "sent": r["commands"]["n"] + r["commands"]["missing"],
                    "late": r["commands"].get("late"),
                    "missing": r["commands"]["missing"],
                },
                "stop_all_missing": [t["missing"] for t in r["stop_all_ms"]["trials"]],
                "stop_all_late": [
                    t.get("late") for t in r["stop_all_ms"]["trials"]
                ],  # counted since 2026-11-28 18:00
                "stop_all_ms": {
                    "p99": r["stop_all_ms"]["p99_over_robots"],
                    "to_last_robot": r["stop_all_ms"]["to_last_robot_max"],
                },
                "live": {
                    "clients": r["live"]["clients"],
                    "robots_seen_per_client_min": r["live"]["robots_seen_per_client"]["min"],
                    "hz_per_robot_min": r["live"]["hz_per_robot_per_client"]["min"],
                    "hz_per_robot_p50": r["live"]["hz_per_robot_per_client"]["p50"],
                    "staleness_p99_ms": r["live"]["staleness_ms"]["p99"],
                    "staleness_p99_under_instructions_ms": r["live"]
                    .get("staleness_ms_under_instructions", {})
                    .get("p99"),  # told apart since 2026-11-29, sixth session: None before
                },
                "cpu_cores_total": r["cpu_cores"]["total"],
                "registered": r["registered"],
                "cpu_ms_per_s_per_robot": round(1000 * r["cpu_cores"]["total"] / max(1, r["registered"]), 2),
                "load_average_at_start": r["load_average_at_start"],
                "instructions": instructed_row(r.get("instructions")),
            }
            for r in sizes
        },
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "REPORT.md").write_text(markdown(summary))
    plot(summary, out / "cost_curve.png")
    if (out.parent / report_file.RUN_FILE).exists():  # bench/results/REPORT.md carries this section too
        report_file.render_all(out.parent)
    return summary


def instructed_row(measured: dict | None) -> dict | None:
    """The instructed phase's figures for the summary (None: a run from before it, 2026-11-29)."""
    if not measured:
        return None
    turn, stop = measured["turn"], measured["stop"]
    return {
        "started_s": {k: _s(turn["started_ms"][k]) for k in ("p50", "p99", "max")},
        "not_started": len(turn["not_started"]),
        "settled_s": turn["settled_s"],
        "statuses": turn["statuses"],
        "turned_ok": turn["turned_ok"],
        "said_true": turn["said_true"],
        "stop_zeros_ms": {k: stop["zeros_ms"][k] for k in ("p99", "max", "missing")},
        "stop_statuses": stop["statuses"],
        "stop_settled_s": stop["settled_s"],
        "at_rest_s": stop["at_rest_s"],
    }


def _s(ms: float | None) -> float | None:
    return None if ms is None else round(ms / 1000, 2)


def markdown(summary: dict) -> str:
    rows = summary["sizes"]
    lines = [
        "## Cluster (issue 19): network namespaces db, web1, web2, exec1, exec2, sim1, sim2, links on one machine",
        "",
        "`python -m bench.cluster --robots N` (deploy/cluster.py). Goals are the issue's, for 1,000 robots.",
        "",
        "| robots | registration (s) | all online (s) | command p50 / p99 (ms) | commands late / missing "
        "| stop-all p99 / last robot (ms) | robots a stop reached late / missed (each trial) "
        "| clients | robots seen per decoding client (min) | pose Hz per robot per client (min / p50) | staleness p99 (ms): teleop / under instructions | CPU cores "
        "| CPU ms/s per robot | load at start |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, r in rows.items():
        live, c = r["live"], r["commands"]
        lines.append(
            f"| {n} | {r['registration_s']} | {r['online_s']} | {r['command_ms']['p50']} / {r['command_ms']['p99']} "
            f"| {c['late']} / {c['missing']} of {c['sent']} "
            f"| {r['stop_all_ms']['p99']} / {r['stop_all_ms']['to_last_robot']} "
            f"| {stop_misses(r)} | {live['clients']} "
            f"| {live['robots_seen_per_client_min']} | {live.get('hz_per_robot_min')} / {live['hz_per_robot_p50']} "
            f"| {live['staleness_p99_ms']} / {live.get('staleness_p99_under_instructions_ms') or '—'} "
            f"| {r['cpu_cores_total']} | {r['cpu_ms_per_s_per_robot']} | {r['load_average_at_start'][0]} |"
        )
    lines += [
        "",
        "Staleness: of the teleop (the rounds and the stop trials) / of the instructions the dashboards' 12 s window "
        "reaches into; — where a run did not tell them apart (before 2026-11-29's sixth session: one figure for both).",
    ]
    instructed = {n: r["instructions"] for n, r in rows.items() if r.get("instructions")}
    if instructed:
        lines += [
            "",
            'Under instructions (after the teleop rounds): "turn left 90 degrees" to every robot, '
            f"{INSTRUCTION_CHUNK} robots an instruction (POST /api/instructions), judged by each shard's odometry; "
            'then "turn left 720 degrees" and the dashboard\'s STOP once 90 % turn.',
            "",
            "| robots | started p50 / p99 / max (s) | not started | all settled (s) | instructions | turned 90 ± "
            f"{TURN_TOLERANCE_DEG:g}° | outcome says what odometry measured (± {SAID_WITHIN_DEG:g}°) "
            "| stop: zeros p99 / last (ms), missing | instructions after the stop | settled / at rest (s) |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for n, i in instructed.items():
            st, z = i["started_s"], i["stop_zeros_ms"]
            lines.append(
                f"| {n} | {st['p50']} / {st['p99']} / {st['max']} | {i['not_started']} | {i['settled_s']} "
                f"| {i['statuses']} | {i['turned_ok']} of {n} | {i['said_true']} of {n} "
                f"| {z['p99']} / {z['max']}, {z['missing']} | {i['stop_statuses']} "
                f"| {i['stop_settled_s']} / {i['at_rest_s']} |"
            )
    goals = summary["goals_for_1000"]
    lines += [
        "",
        f"Goals (1,000 robots): registration ≤ {goals['registration_s']:g} s; 50 clients each receiving every robot "
        f"at ≥ {goals['live_hz']:g} Hz with staleness p99 ≤ {goals['staleness_p99_ms']:g} ms; command p99 ≤ "
        f"{goals['command_p99_ms']:g} ms with all moving; stop-all p99 ≤ {goals['stop_all_p99_ms']:g} ms to the "
        "last robot. A command seen after its round (5 s) is late, one never seen missing; a stop trial waits 5 s,"
        " and its zeros are counted at the end of the run as the commands are (runs before 2026-11-28 18:00 counted"
        " a late zero as missed).",
        "",
    ]
    return "\n".join(lines)


def stop_misses(size: dict) -> str:
    """Each trial's robots its zero reached late / never reached ("?" late: a run that did not count them)."""
    late = size.get("stop_all_late") or [None] * len(size["stop_all_missing"])
    return ", ".join(
        f"{'?' if n is None else n} / {m}" for n, m in zip(late, size["stop_all_missing"], strict=True)
    )


def plot(summary: dict, path: Path) -> None:
    """The cost curve: command and stop latency (p99) and CPU per robot against the number of robots."""
    # Deferred: matplotlib takes seconds to import and only the plots need it.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after use("Agg"): pyplot picks its backend when imported

    sizes = summary["sizes"]
    robots = [int(n) for n in sizes]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for label, values in (
        ("command p99", [sizes[str(n)]["command_ms"]["p99"] for n in robots]),
        ("stop-all, last robot", [sizes[str(n)]["stop_all_ms"]["to_last_robot"] for n in robots]),
        ("pose staleness p99", [sizes[str(n)]["live"]["staleness_p99_ms"] for n in robots]),
    ):
        left.plot(robots, values, marker="o", label=label)
    left.set(xlabel="robots", ylabel="ms", title="latency (cluster, one 2-core machine)")
    left.legend()
    right.plot(robots, [sizes[str(n)]["cpu_ms_per_s_per_robot"] for n in robots], marker="o")
    right.set(xlabel="robots", ylabel="CPU ms per s per robot", title="CPU per robot (all hosts)")
    for axis in (left, right):
        axis.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.cluster", description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, nargs="*", default=[100], help="total robots (two shards)")
    parser.add_argument("--clients", type=int, default=50, help="browser-like WebSocket clients")
    parser.add_argument("--rounds", type=int, default=10, help="teleop rounds to every robot")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--report", action="store_true", help="only remake summary.json, REPORT.md, the plot")
    parser.add_argument("--keep", action="store_true", help="leave the cluster up after the last size")
    args = parser.parse_args(argv)
    if not args.report:
        reason = reason_unavailable()
        if reason:
            print(f"bench.cluster: not run: {reason}", file=sys.stderr)
            return 1
        for robots in args.robots:
            if robots < 2 or robots % 2:
                parser.error("--robots: an even number of 2 or more (two shards)")
            run_size(robots, args.clients, args.rounds, args.out, keep=args.keep)
    summary = report(args.out)
    print(json.dumps(summary["sizes"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
