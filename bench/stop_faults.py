"""Stops under faults: time to the zero at the robot, per fault and stop path, median and p99.

    python -m bench.stop_faults [--quick | --full] [--out DIR]

runs tests/execution/test_stop_faults.py (two simulated robots driving; a Redis of its own frozen or refusing
writes, the database locked, a flooding endpoint, a hung worker, and no fault; each stop path: "stop" typed over
the page socket, the STOP ALL form, POST /api/instructions "stop"; and, with no fault, `manage.py instruct "stop"`
in a process of its own while `manage.py robotlinks` runs: cli_stop) several rounds, asks it for its figures
(FLEET_STOP_FAULTS_OUT) and writes DIR/stop_faults.json (bench/results/ by default) with the table. The zero is
seen when every robot's simulated body holds a zero command (polled every ~5 ms); times are from the request (the
CLI's: its request to the links process's stop socket; its answer is the command's end, after the grammar and the
bookkeeping), and for the CLI also from the command's start (the process spawned: Python and Django start-up).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from bench.chaos import run_suite

BASE_DIR = Path(__file__).resolve().parent.parent
RESULTS = BASE_DIR / "bench" / "results"
SUITE = "tests/execution/test_stop_faults.py"
ROUNDS = {"quick": 2, "full": 10}


def run(rows_file: Path, rounds: int) -> int:
    return run_suite(
        SUITE, {"FLEET_STOP_FAULTS_OUT": str(rows_file), "FLEET_STOP_FAULTS_ROUNDS": str(rounds)}
    )


def p99(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]


def summarize(rows: list[dict]) -> list[dict]:
    """One line per (fault, path): n, median and p99 of the time to the zero and to the answer, worst status."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        groups.setdefault((row["fault"], row["path"]), []).append(row)
    table = []
    for (fault, path), group in groups.items():
        zero, answer = [r["zero_ms"] for r in group], [r["answer_ms"] for r in group]
        table.append(
            {
                "fault": fault,
                "path": path,
                "n": len(group),
                "zero_ms_median": round(statistics.median(zero), 1),
                "zero_ms_p99": round(p99(zero), 1),
                "answer_ms_median": round(statistics.median(answer), 1),
                "answer_ms_p99": round(p99(answer), 1),
                "worst_status": max(r["status"] for r in group),
            }
        )
        started = [r["start_zero_ms"] for r in group if "start_zero_ms" in r]
        if started:  # the CLI: from the command's start too
            table[-1] |= {
                "start_zero_ms_median": round(statistics.median(started), 1),
                "start_zero_ms_p99": round(p99(started), 1),
            }
    return table


def markdown(table: list[dict]) -> str:
    lines = [
        "| fault | stop path | n | zero at the robot, median / p99 (ms) | answer, median / p99 (ms) | status |",
        "|---|---|---|---|---|---|",
    ]
    for r in table:
        lines.append(
            f"| {r['fault']} | {r['path']} | {r['n']} | {r['zero_ms_median']} / {r['zero_ms_p99']} "
            f"| {r['answer_ms_median']} / {r['answer_ms_p99']} | {r['worst_status']} |"
        )
    for r in table:
        if "start_zero_ms_median" in r:
            lines.append(
                f"\n{r['path']}: zero at the robot from the command's start (process start-up included), "
                f"median / p99: {r['start_zero_ms_median']} / {r['start_zero_ms_p99']} ms"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_const", const="quick", dest="mode")
    group.add_argument("--full", action="store_const", const="full", dest="mode")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    mode = args.mode or "full"
    rows_file = Path(tempfile.mkdtemp(prefix="stop-faults-")) / "rows.json"
    status = run(rows_file, ROUNDS[mode])
    rows = json.loads(rows_file.read_text()) if rows_file.exists() else []
    table = summarize(rows)
    document = {
        "what": __doc__.splitlines()[0],
        "mode": mode,
        "at": time.strftime("%Y-%m-%d %H:%M:%S"),
        "suite_exit": status,
        "stop_faults": table,
        "rows": rows,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "stop_faults.json").write_text(json.dumps(document, indent=2) + "\n")
    print(markdown(table))
    return 0 if status == 0 and rows else 1


if __name__ == "__main__":
    sys.exit(main())
