"""The fleet across hosts (issue 19): network namespaces on one machine as db, web1, web2, exec1, exec2, sim1,
sim2 and links (deploy/cluster.py), each process configured by the environment only.

One walk through, in order, because each step starts from what the one before left: bulk registration of both
shards through web1's API; an instruction per robot, judged by the simulator's odometry; every process of exec1
killed (kill -9) mid-work; web1 killed; sim1 killed and started again. Motion and rest are read from the
simulator's own odometry, never from the portal's word. The deadlines are the issue's (10 s for a lost executor
host); the others are bounds for this loaded 2-core machine and say so.
"""

from __future__ import annotations

import math
import time

import pytest
import redis

from deploy.cluster import address
from deploy.cluster_client import Odometry, Portal

pytestmark = [pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(420)]

FINAL = {"succeeded", "failed", "cancelled", "refused", "answered"}
EXEC_HOST_DEADLINE_S = 10.0  # issue 19: a lost executor host's robots at rest and instructions settled within
LINKS_NOTICE_S = 20.0  # a shard's links drop and their robots go offline (not an issue deadline)


def wait(condition, timeout: float, what: str, poll: float = 0.1, explain=None) -> float:
    """Seconds until condition() held (said, for the log); AssertionError naming what did not happen otherwise,
    with what explain() returns then (the state that tells why)."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if condition():
            took = time.monotonic() - start
            print(f"cluster test: {what}: {took:.1f} s", flush=True)
            return took
        time.sleep(poll)
    raise AssertionError(f"not within {timeout:g} s: {what}" + (f"; {explain()}" if explain else ""))


def lock_owners(robots: dict[str, dict]) -> dict[str, str]:
    """Robot name -> the host whose executor holds its Redis lock (the token starts with the hostname)."""
    client = redis.Redis(host=address("db"), port=6379, socket_timeout=2)
    owners = {}
    for name, robot in robots.items():
        token = client.get(f"fleet:exec:lock:{robot['id']}")
        if token:
            owners[name] = token.decode().split(":", 1)[0]
    return owners


def log_tail(cluster, name: str, lines: int = 20) -> list[str]:
    """The last lines of one process's log in the cluster (what it did while the test waited)."""
    path = cluster.log_dir / name
    return path.read_text(errors="replace").splitlines()[-lines:] if path.exists() else [f"{path}: none"]


def distance_from(points, place: dict) -> float:
    """The mean distance from the points to the place."""
    points = list(points)
    return sum(math.hypot(place["x"] - x, place["y"] - y) for x, y in points) / len(points)


def test_the_fleet_survives_losing_an_executor_host_a_web_host_and_a_simulator_shard(cluster):
    shards = {cluster.sim_url(host): cluster.shard_robots(host) for host in ("sim1", "sim2")}
    names = [name for robots in shards.values() for name in robots]
    portal = Portal(cluster.url("web1")).login()

    # Bulk registration of both shards' endpoints through web1's API (queued, run by a control worker).
    records = portal.register(list(shards))
    assert [record["error"] for record in records] == ["", ""]
    assert sorted(robot for record in records for robot in record["robots"]) == sorted(names)
    wait(
        lambda: (
            all(r["link_status"] == "online" for r in portal.robots().values())
            and len(portal.robots()) == len(names)
        ),
        60,
        "every robot online through the links host",
        poll=0.5,
    )

    with Odometry(shards) as odometry:
        wait(lambda: odometry.fresh(names), 15, "odometry from both shards")
        start = {name: (odometry.motion[name].x, odometry.motion[name].y) for name in names}
        assert odometry.at_rest(names)

        # An instruction per robot, to the places far from the robots in turn (spread out, so few goals clash).
        robots = portal.robots()
        places = sorted(portal.get("locations"), key=lambda p: -distance_from(start.values(), p))
        instruction_of = {}
        for index, name in enumerate(names):
            place = places[index % max(1, len(places) // 2)]
            body = {"robot_ids": [robots[name]["id"]], "destination": {"location": place["id"]}}
            instruction_of[name] = portal.post("instructions", body)["id"]
        driven = {}

        def moved(name: str) -> bool:
            now = odometry.motion[name]
            return math.dist(start[name], (now.x, now.y)) > 0.05

        def moving_from_both_exec_hosts() -> bool:
            owners = lock_owners(robots)
            moving = {name for name in names if moved(name)}
            driven.clear()
            for name, host in owners.items():
                if name in moving:
                    driven.setdefault(host, []).append(name)
            # mid-work: one of exec1's robots under way right now
            return {"exec1", "exec2"} <= set(driven) and bool(odometry.moving(driven["exec1"]))

        wait(
            moving_from_both_exec_hosts,
            60,
            "robots driven (moved) by executors on exec1 and on exec2",
            poll=0.2,
        )
        on_exec1 = sorted(driven["exec1"])
        # what exec1 runs on them now: the test's own instruction, or one the system put first (a make_way the
        # robot was asked for before its own instruction came, which then queued behind it)
        running = {n: (portal.get(f"robots/{n}/queue")["running"] or {}).get("instruction") for n in on_exec1}

        # exec1 lost: every process of the host killed mid-work. Its robots come to rest and the instructions it
        # ran are settled (failed "executor lost", docs/fault-survival.md, "Executor lost") within 10 s; work
        # queued behind them goes on on exec2 (or is settled).
        killed = cluster.kill_host("exec1")
        assert len(killed) >= 2  # the executor and the control worker (and its pool)
        lost = time.monotonic()

        def status(pk: int) -> str:
            return portal.get(f"instructions/{pk}")["status"]

        def settled() -> bool:
            return all(status(pk) in FINAL for pk in running.values() if pk)

        def taken_over() -> bool:
            owners = lock_owners({n: robots[n] for n in on_exec1})
            return all(status(instruction_of[n]) in FINAL or owners.get(n) == "exec2" for n in on_exec1)

        wait(
            lambda: odometry.at_rest(on_exec1),
            EXEC_HOST_DEADLINE_S,
            f"{on_exec1} at rest after exec1 was lost",
        )
        wait(
            settled,
            max(0.1, EXEC_HOST_DEADLINE_S - (time.monotonic() - lost)),
            f"the instructions exec1 ran on {on_exec1} settled",
            explain=lambda: {
                "running then": running,
                "statuses": {pk: status(pk) for pk in running.values() if pk},
                "scheduler log": log_tail(cluster, "links-scheduler.log"),
            },
        )
        wait(
            taken_over,
            15,
            "exec1's robots' own instructions settled or run on by exec2",
            explain=lambda: {n: (status(instruction_of[n]), lock_owners(robots).get(n)) for n in on_exec1},
        )

        # web1 lost: the same session carries on on web2 (sessions are in the shared database); a stop sent there
        # reaches every robot, wherever its executor and its shard.
        cluster.kill_host("web1")
        portal = portal.on(cluster.url("web2"))
        assert sorted(portal.robots()) == sorted(names)
        portal.post("instructions", {"text": "stop"})
        wait(lambda: odometry.at_rest(names), 10, "every robot at rest after a stop through web2")

        # exec1's robots, sent again (the others stand still, so traffic has none of them wait for long): exec2
        # drives them now.
        resent = {}
        for index, name in enumerate(on_exec1):
            place = places[index % len(places)]
            body = {"robot_ids": [robots[name]["id"]], "destination": {"location": place["id"]}}
            resent[name] = portal.post("instructions", body)["id"]
        wait(
            lambda: bool(odometry.moving(on_exec1)),
            30,
            "exec1's robots moving again, sent through web2",
            explain=lambda: {name: portal.get(f"instructions/{pk}") for name, pk in resent.items()},
        )
        assert set(lock_owners({name: robots[name] for name in on_exec1}).values()) <= {"exec2"}
        portal.post("instructions", {"text": "stop"})
        wait(lambda: odometry.at_rest(names), 10, "every robot at rest after a second stop through web2")

        # sim1 lost: its robots go offline with an alert each; back online (and the alerts resolved) when it returns.
        on_sim1 = shards[cluster.sim_url("sim1")]
        cluster.kill_host("sim1")

        def offline_with_alerts() -> bool:
            robots_now = portal.robots()
            alerted = {
                a["robot"] for a in portal.get("alerts?status=open&limit=500") if a["kind"] == "robot_offline"
            }
            return all(robots_now[n]["link_status"] == "offline" for n in on_sim1) and set(on_sim1) <= alerted

        wait(
            offline_with_alerts,
            LINKS_NOTICE_S,
            f"{on_sim1} offline with a robot_offline alert each",
            poll=0.5,
        )
        assert all(portal.robots()[n]["link_status"] == "online" for n in shards[cluster.sim_url("sim2")])
        cluster.start_host("sim1")

        def back() -> bool:
            robots_now = portal.robots()
            alerted = {
                a["robot"] for a in portal.get("alerts?status=open&limit=500") if a["kind"] == "robot_offline"
            }
            return (
                all(robots_now[n]["link_status"] == "online" for n in on_sim1) and not set(on_sim1) & alerted
            )

        wait(back, 60, f"{on_sim1} online again and their alerts resolved", poll=0.5)
        wait(lambda: odometry.fresh(on_sim1), 15, "sim1's odometry again")
