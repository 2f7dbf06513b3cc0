"""Experiments that need the execution engine (fleet.control, Celery tasks): 4 via the portal, 5, 6, 7, stop.

Instructions go in through `fleet.instructions.submit` (what the API's POST /api/instructions calls) and are
followed through the timestamps execution stores on each Instruction.
"""

import asyncio
import time

from bench import paper
from bench.drivers import Unavailable
from bench.stats import summarize

FINAL = {"succeeded", "failed", "cancelled", "refused", "needs_user"}
TARGETS = ("A", "B", "C")  # the paper's (x0, y0), (x1, y1), (x2, y2): locations of the demo world


def _require_execution() -> None:
    try:
        import fleet.control
        import fleet.tasks  # noqa: F401
    except ImportError as exc:
        raise Unavailable(f"execution engine not there yet ({exc.name} missing)") from exc


async def submit_and_wait(bench, text: str, timeout: float | None = None) -> dict:
    """Submit as the bench user and wait for a final status; return the instruction's timings."""
    from fleet.instructions import submit
    from fleet.models import Instruction

    instruction = await asyncio.to_thread(submit, text, bench.portal.user, "api")
    deadline = time.time() + (timeout or (60.0 if bench.mode == "full" else 20.0))
    while time.time() < deadline:
        row = await asyncio.to_thread(Instruction.objects.get, pk=instruction.pk)
        if row.status in FINAL:
            break
        await asyncio.sleep(0.05)
    total = (row.finished_at - row.received_at).total_seconds() if row.finished_at else None
    bench.outcomes.append(
        {"status": row.status, "outcome": row.outcome[:200], "error": row.error[:200], "text": text}
    )
    if len(bench.outcomes) >= 2 and not any(o["status"] == "succeeded" for o in bench.outcomes):
        first = bench.outcomes[0]
        raise RuntimeError(
            f"the first instructions did not succeed ({first['text']!r}: {first['status']} "
            f"{first['outcome'] or first['error'] or 'no outcome within the timeout'})"
        )
    return {
        "id": row.pk,
        "text": text,
        "status": row.status,
        "type": row.type,
        "total_s": total,
        "outcome": row.outcome,
        "error": row.error,
    }


async def exp5_move(bench) -> dict:
    """Table 7: 1, 2, 4 robots moved to one, two, three targets (one instruction)."""
    cells = []
    for row, n in (("SingleRobot", 1), ("TwoRobots", 2), ("FourRobots", 4)):
        names = " and ".join(bench.fleet_names(n))
        for col, k in enumerate((1, 2, 3)):
            text = f"move {names} to {' then '.join(TARGETS[:k])}"
            runs = [await submit_and_wait(bench, text) for _ in range(bench.cfg["repeats"])]
            stats = summarize([r["total_s"] for r in runs if r["status"] == "succeeded"])
            cells.append(
                {
                    "table": 7,
                    "section": "Average move time (s)",
                    "row": row,
                    "column": col,
                    "value": stats["p50"],
                    "n": stats["n"],
                }
            )
    return {
        "title": "Experiment 5: move to locations",
        "status": "ok",
        "reason": "",
        "notes": [],
        "cells": cells,
    }


async def exp6_sequence(bench) -> dict:
    """Table 8: one, two, three sequential instructions for 1, 2, 4 robots."""
    cells = []
    for row, n in (("SingleRobot", 1), ("TwoRobots", 2), ("FourRobots", 4)):
        names = " and ".join(bench.fleet_names(n))
        for col, k in enumerate((1, 2, 3)):
            t0 = time.time()
            runs = [await submit_and_wait(bench, f"move {names} to {target}") for target in TARGETS[:k]]
            ok = all(r["status"] == "succeeded" for r in runs)
            cells.append(
                {
                    "table": 8,
                    "section": "Average competition time (s)",
                    "row": row,
                    "column": col,
                    "value": round(time.time() - t0, 3) if ok else None,
                    "n": 1,
                }
            )
    return {
        "title": "Experiment 6: sequential instructions",
        "status": "ok",
        "reason": "",
        "notes": [],
        "cells": cells,
    }


async def exp7_success(bench) -> dict:
    """Tables 13 and 14: type IV instructions per robot per slot, without and with navigation."""
    trials = 20 if bench.mode == "full" else 2
    cells, rates = [], {"no_nav": [], "nav": []}
    names = {"Turtlebot": "turtlebot", "Husky": "husky", "TiaGo": "tiago"}
    for table, kind, verb in ((13, "no_nav", "shift"), (14, "nav", "navigate")):
        section = paper.TABLES[table].sections[0].name
        for row, goals in paper.SCHEDULE_12.items():
            for col, goal in enumerate(goals):
                if goal is None:
                    continue
                runs = [
                    await submit_and_wait(bench, f"{verb} {names[row]} to {goal[0]}") for _ in range(trials)
                ]
                rate = sum(r["status"] == "succeeded" for r in runs) / trials
                rates[kind].append(rate)
                cells.append(
                    {
                        "table": table,
                        "section": section,
                        "row": row,
                        "column": col,
                        "value": rate,
                        "n": trials,
                    }
                )
    summary = {"success_rate": {k: round(sum(v) / len(v), 3) if v else None for k, v in rates.items()}}
    return {
        "title": "Experiment 7: success rates (Tables 13, 14)",
        "status": "ok",
        "reason": "",
        "notes": [f"{trials} trials per robot per slot; FreeTime slots have no goal"],
        "cells": cells,
        "summary": summary,
    }


EXPERIMENTS = {"exp5_move": exp5_move, "exp6_sequence": exp6_sequence, "exp7_success": exp7_success}


async def run(bench, name: str) -> dict:
    _require_execution()
    if name not in EXPERIMENTS:
        raise Unavailable(f"{name}: not written yet (needs the execution engine's interfaces to settle)")
    bench.outcomes = []
    out = await EXPERIMENTS[name](bench)
    failed = [o for o in bench.outcomes if o["status"] != "succeeded"]
    out["failures"] = failed[:20]
    if failed and len(failed) == len(bench.outcomes):
        out["status"], out["summary"] = "error", {}
        out["reason"] = (
            f"no instruction succeeded; first: {failed[0]['status']}: {failed[0]['outcome'] or failed[0]['error']}"
        )
    return out
