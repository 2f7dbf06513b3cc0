"""Fault survival: the chaos suite's figures as a result file and docs/fault-survival.md's table.

    python -m bench.chaos [--out DIR]

runs tests/chaos/test_process_kill.py (a whole `make run` in a folder and on ports of its own; each process
killed with SIGKILL while the turtlebot drives an instruction, then garbage on its link; judged by its odometry)
and writes what each fault cost to DIR/chaos.json (bench/results/ by default), then prints the table as
docs/fault-survival.md shows it. The scenarios and their assertions are the tests' own: this only asks them for their
figures (FLEET_CHAOS_OUT) and says whether they held. A few minutes on a 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

BASE_DIR = Path(__file__).resolve().parent.parent
SUITE = "tests/chaos/test_process_kill.py"
COLUMNS = {  # docs/fault-survival.md's columns, from the suite's row keys
    "fault (kill -9)": "fault",
    "robot at rest (s)": "robot at rest (s)",
    "instruction final (s)": "instruction final (s)",
    "new pid (s)": "process back (s)",
    "page loads failed / sent": "requests failed / sent",
    "instruction": "the instruction",
}


def run(out: Path) -> int:
    """The suite, with its figures going to out; pytest's exit status."""
    return run_suite(SUITE, {"FLEET_CHAOS_OUT": str(out)})


def run_suite(suite: str, env: dict[str, str]) -> int:
    """A test module as a bench runs it (make test's wrapper, no plugins that reorder or cache), with env added;
    pytest's exit status. The module writes its figures where env says."""
    command = [
        sys.executable,
        "-m",
        "fleet.testrun",
        suite,
        "-q",
        "-p",
        "no:randomly",
        "-p",
        "no:cacheprovider",
    ]
    return subprocess.call(command, cwd=BASE_DIR, env=os.environ | env)


def table(document: dict) -> str:
    """The figures as a Markdown table."""
    lines = ["| " + " | ".join(COLUMNS.values()) + " |", "|" + "---|" * len(COLUMNS)]
    for row in document["faults"]:
        lines.append("| " + " | ".join(str(row.get(key, "–")) for key in COLUMNS) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=BASE_DIR / "bench" / "results", help="folder for chaos.json"
    )
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    out = args.out / "chaos.json"
    out.unlink(missing_ok=True)
    status = run(out)
    if not out.exists():
        print(f"bench.chaos: the suite wrote no figures (exit status {status})")
        return status or 1
    document = json.loads(out.read_text())
    document["suite_passed"] = status == 0
    out.write_text(json.dumps(document, indent=2) + "\n")
    print(table(document))
    print(f"\n{out} ({'every assertion held' if status == 0 else f'the suite failed: status {status}'})")
    return status


if __name__ == "__main__":
    sys.exit(main())
