"""The paper's tables beside ours, for the experiments page and its exports.

"Ours" is a set of cells, each {table, section, row, column, value, n, note}, keyed like the paper's printed cells.
Two sources give them: the last benchmark run (`make bench` writes bench/results/*.json, committed with the
repository; read here as data, bench/ is never imported) and a response run from the page (Table 5's grid, one
robot at a time). bench/report.py renders the same comparison as Markdown for REPORT.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from django.conf import settings

from experiments import paper

BENCH_RESULTS = Path(settings.BASE_DIR) / "bench" / "results"
RUN_FILE = "run.json"
BENCH = "bench"


@dataclass(frozen=True)
class Source:
    """Where our numbers come from: "bench", or "run-<pk>-<robot>" for one robot of a page run."""

    key: str
    label: str
    cells: tuple[dict, ...]


def bench_source(results_dir: Path = BENCH_RESULTS) -> Source | None:
    """The cells of the last benchmark run, or None when there is none (or it cannot be read)."""
    try:
        run = json.loads((results_dir / RUN_FILE).read_text())
        cells = []
        for name in run["experiments"]:
            path = results_dir / f"{name}.json"
            if path.exists():
                cells += json.loads(path.read_text()).get("cells", [])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    meta = run.get("meta") or {}
    label = f"last benchmark ({run.get('mode', '?')} run at {meta.get('at', '?')}, bench/results/)"
    return Source(BENCH, label, tuple(c for c in cells if isinstance(c, dict)))


def run_sources(runs) -> list[Source]:
    """One source per robot of each finished response run."""
    sources = []
    for run in runs:
        if run.kind != "response" or run.status != "succeeded":
            continue
        for robot, measured in (run.results or {}).get("robots", {}).items():
            key = f"run-{run.pk}-{robot}"
            label = f"run #{run.pk}, {robot} ({run.started_at:%Y-%m-%d %H:%M})"
            sources.append(Source(key, label, tuple(measured.get("cells", []))))
    return sources


def compare(table: paper.PaperTable, cells) -> dict:
    """One paper table with our value beside each printed one: what the page's table, plot and CSV show."""
    ours = {(c["table"], c["section"], c["row"], c["column"]): c for c in cells}
    sections, notes = [], set()
    for section in table.sections:
        rows = []
        for row in section.rows:
            pairs = []
            for column, printed in enumerate(row.values):
                cell = ours.get((table.number, section.name, row.label, column))
                if cell and cell.get("note"):
                    notes.add(cell["note"])
                pairs.append(
                    {
                        "paper": printed,
                        "ours": cell.get("value") if cell else None,
                        "n": cell.get("n") if cell else None,
                    }
                )
            rows.append({"label": row.label, "cells": pairs})
        sections.append({"name": section.name, "rows": rows})
    return {
        "number": table.number,
        "title": table.title,
        "unit": table.unit,
        "row_quantity": table.row_quantity,
        "column_quantity": table.column_quantity,
        "columns": list(table.columns),
        "sections": sections,
        "notes": [*table.notes, *sorted(notes)],
        "measured": sum(p["ours"] is not None for s in sections for r in s["rows"] for p in r["cells"]),
    }


def compare_all(cells) -> list[dict]:
    """Every paper table, in the paper's order, compared with these cells."""
    return [compare(table, cells) for table in paper.TABLES.values()]


def comparison_rows(tables: list[dict]) -> list[dict]:
    """The comparisons flattened, one row per printed cell (the CSV export)."""
    return [
        {
            "table": t["number"],
            "section": s["name"],
            "row": r["label"],
            "column": t["columns"][i],
            "unit": t["unit"],
            "paper": p["paper"],
            "ours": p["ours"],
            "n": p["n"],
        }
        for t in tables
        for s in t["sections"]
        for r in s["rows"]
        for i, p in enumerate(r["cells"])
    ]


def run_rows(run) -> list[dict]:
    """A page run's results flattened for CSV: one row per measured cell (response) or per robot (success)."""
    results = run.results or {}
    rows = []
    for robot, measured in results.get("robots", {}).items():
        if run.kind == "response":
            rows += [
                {
                    "run": run.pk,
                    "robot": robot,
                    "table": c.get("table"),
                    "section": c.get("section"),
                    "row": c.get("row"),
                    "column": paper.SPEED_COLUMNS[c["column"]]
                    if c.get("column") in range(3)
                    else c.get("column"),
                    "value": c.get("value"),
                    "n": c.get("n"),
                }
                for c in measured.get("cells", [])
            ]
        else:
            rows.append({"run": run.pk, "robot": robot, "goal": results.get("goal"), **measured})
    return rows


def run_summary(run) -> list[dict]:
    """A page run's results per robot, in a few numbers (the runs table; the exports hold everything)."""
    results = run.results or {}
    out = []
    for robot, measured in results.get("robots", {}).items():
        if run.kind == "response":
            start, stop = measured.get("start_s") or {}, measured.get("stop_s") or {}
            out.append(
                {
                    "robot": robot,
                    "start_p50": start.get("p50"),
                    "start_p99": start.get("p99"),
                    "stop_p50": stop.get("p50"),
                    "stop_p99": stop.get("p99"),
                    "n": start.get("n"),
                    "note": measured.get("cap", ""),
                    "source": f"run-{run.pk}-{robot}",
                }
            )
        else:
            out.append({"robot": robot, **measured})
    return out
