"""Start/stop response (the paper's experiments 1-4, Tables 3-6) and command latency (portal vs direct).

Start response: command issued -> first odometry sample showing motion. Stop response: stop issued -> first
odometry sample showing the robot still. Received: command issued -> the simulator's endpoint got it.
"""

import asyncio
import time

from experiments import paper
from experiments.probe import OdomWatch, Reception, RobotLink
from experiments.stats import p50_p99, summarize

ODOM_WATCH_MAX = 16  # with more robots, watch the odometry of 16 of them (reception is timed for all)


async def settle(watches: list[OdomWatch], timeout: float = 3.0) -> None:
    """Wait until every watched robot reports itself still."""
    since = time.time()
    await asyncio.gather(*(w.still(since, timeout) for w in watches))


async def start_stop_trial(
    driver,
    links: list[RobotLink],
    watches: dict[str, OdomWatch],
    reception: Reception,
    linear: float,
    angular: float,
    hold_s: float,
) -> list[dict]:
    """One start, hold, stop of all `links` together; one record per robot."""
    watched = [watches[link.name] for link in links if link.name in watches]
    await settle(watched)
    t0 = await driver.start(links, linear, angular)
    moving = await asyncio.gather(*(w.moving(t0) for w in watched))
    await asyncio.sleep(hold_s)
    t1 = await driver.stop(links)
    still = await asyncio.gather(*(w.still(t1) for w in watched))
    motion = {w.link.name: (m, s) for w, m, s in zip(watched, moving, still, strict=True)}
    records = []
    for link in links:
        m, s = motion.get(link.name, (None, None))
        rx, stop_rx = reception.first_after(link, t0), reception.first_after(link, t1, zero=True)
        records.append(
            {
                "robot": link.name,
                "robots": len(links),
                "linear": linear,
                "angular": angular,
                "start_s": None if m is None else m - t0,
                "stop_s": None if s is None else s - t1,
                "received_ms": None if rx is None else (rx - t0) * 1000,
                "stop_received_ms": None if stop_rx is None else (stop_rx - t1) * 1000,
            }
        )
    return records


def cap_note(link: RobotLink) -> str:
    return (
        f"{link.name} capped at {link.max_linear} m/s and {link.max_angular} rad/s (its limits); the paper's "
        f"0.5/1.0/1.5 m/s columns all run at {link.max_linear} m/s"
    )


async def speed_grid(
    driver, link: RobotLink, watches, reception, repeats: int, hold_s: float, table: int, on_cell=None
) -> dict:
    """The paper's linear x angular grid on one robot, as Table 3, 4 or 5; `on_cell()` (a coroutine function,
    optional) is awaited after each cell, for a run's progress."""
    records, cells = [], []
    for col, u in enumerate(paper.LINEAR_SPEEDS):
        for w in paper.ANGULAR_SPEEDS:
            v_cmd, w_cmd = link.cap(u, w)
            batch = []
            for _ in range(repeats):
                batch += await start_stop_trial(driver, [link], watches, reception, v_cmd, w_cmd, hold_s)
            records += [{**r, "paper_linear": u, "paper_angular": w} for r in batch]
            for section, key, sym in (
                ("StartResponse (s)", "start_s", "s"),
                ("StopResponse (s)", "stop_s", "e"),
            ):
                stats = summarize([r[key] for r in batch])
                cells.append(
                    {
                        "table": table,
                        "section": section,
                        "row": f"ω_z^{sym} = {w} rad/s",
                        "column": col,
                        "value": stats["p50"],
                        "n": stats["n"],
                        "note": cap_note(link),
                    }
                )
            if on_cell is not None:
                await on_cell()
    return {
        "records": records,
        "cells": cells,
        "cap": cap_note(link),
        "received_ms": summarize([r["received_ms"] for r in records]),
        "start_s": summarize([r["start_s"] for r in records]),
        "stop_s": summarize([r["stop_s"] for r in records]),
    }


ROBOT_ROWS = {1: "SingleRobot", 2: "TwoRobots", 4: "FourRobots"}


async def robots_scale(
    driver, links: list[RobotLink], watches, reception, counts: list[int], repeats: int, hold_s: float
) -> dict:
    """Experiment 4: 1, 2, 4 robots over the linear speeds (Table 6), then 8 ... N at one speed."""
    cells, points = [], []
    for n, row in ROBOT_ROWS.items():
        if n > len(links):
            continue
        for col, u in enumerate(paper.LINEAR_SPEEDS):
            v_cmd, _ = links[0].cap(u, 0.0)
            batch = []
            for _ in range(repeats):
                batch += await start_stop_trial(driver, links[:n], watches, reception, v_cmd, 0.0, hold_s)
            for section, key in (("StartResponse (s)", "start_s"), ("StopResponse (s)", "stop_s")):
                stats = summarize([r[key] for r in batch])
                cells.append(
                    {
                        "table": 6,
                        "section": section,
                        "row": row,
                        "column": col,
                        "value": stats["p50"],
                        "n": stats["n"],
                        "note": cap_note(links[0]) + "; angular 0",
                    }
                )
    for n in counts:
        batch = []
        for _ in range(repeats):
            batch += await start_stop_trial(
                driver, links[:n], watches, reception, links[0].max_linear, 0.0, hold_s
            )
        points.append(
            {
                "robots": n,
                **{
                    k: summarize([r[k] for r in batch])
                    for k in ("start_s", "stop_s", "received_ms", "stop_received_ms")
                },
            }
        )
    return {"cells": cells, "points": points}


async def command_latency(
    driver, links: list[RobotLink], reception: Reception, counts: tuple[int, ...], rounds: int
) -> dict:
    """Command issued -> received at the robot's endpoint, all n robots moving; {n: {p50, p99}} in ms.

    Before the samples, one zero command per robot opens the links and runs the per-press checks, and the
    portal gets a second to settle: what is measured is a fleet under way. (A burst of n first presses is
    itself slower: one batched check. The first round after it was once seen ~90 ms late with 100 robots;
    three later runs without the settling second did not show it: 15-19 ms at most.)
    """
    out, raw = {}, {}
    for n in counts:
        if n > len(links):
            continue
        samples = []
        await driver.warm_up(links[:n])
        await asyncio.sleep(1.0)  # the portal's write-behind audit and grant re-check of the first presses
        for i in range(rounds):
            angular = round(0.05 + 0.001 * (i % 500), 6)  # unique per round, to match what arrives
            t0 = await driver.start(links[:n], links[0].max_linear * 0.5, angular)
            await asyncio.sleep(0.15 if n < 50 else 0.4)
            samples += [
                ((t - t0) * 1000 if t else None)
                for t in (reception.first_after(link, t0, angular=angular) for link in links[:n])
            ]
        await driver.stop(links[:n])
        lost = sum(s is None for s in samples)
        raw[str(n)] = {**summarize(samples), "lost": lost}
        out[str(n)] = p50_p99(samples)
        await asyncio.sleep(0.5)
    return {"summary": out, "detail": raw}
