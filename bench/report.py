"""Turn experiment results into summary.json, one JSON per experiment, REPORT.md and PNG plots.

An experiment result is a dict: {"title", "status": "ok"|"partial"|"skipped"|"error", "reason",
"cells": [{"table", "section", "row", "column", "value", "n"}], "summary": {summary key: value}, "notes": [...],
"profile": "text", ...}. Cells place our medians in the paper's tables, so the report shows both side by side.
"""

import json
import sys
from pathlib import Path

from bench.typed_stop import GOAL_MS, KINDS
from experiments import paper

RUN_FILE = "run.json"  # the run's mode, when and how long, and its experiments in order
SUMMARY_KEYS = (
    "command_latency_ms",
    "direct_latency_ms",
    "relay_latency_ms",
    "stop_latency_ms",
    "typed_stop_latency_ms",
    "registration_s",
    "identification_ms_1200_topics",
    "interpreter_per_s",
    "sim_realtime_robots",
    "live_staleness_ms",
    "success_rate",
    "coordination",
    "allocation_ms_1000",
    "stop_faults",
    "cost_ms_per_s_per_robot",
)
CROWDS = ("2", "4", "8", "16", "32")  # robots sent at once in the coordination bench

# (summary path, comparison, threshold, what the issue asks, how our value reads)
GOALS = (
    (("command_latency_ms", "1", "p99"), "<=", 20, "command to robot p99 ≤ 20 ms, 1 robot", "{:.1f} ms"),
    (("command_latency_ms", "100", "p99"), "<=", 50, "command to robot p99 ≤ 50 ms, 100 moving", "{:.1f} ms"),
    (("stop_latency_ms", "p99"), "<=", 20, "stop p99 ≤ 20 ms with 100 instructions queued", "{:.1f} ms"),
    (("typed_stop_latency_ms", "p99"), "<=", 20, "typed stop p99 ≤ 20 ms, 10 robots moving", "{:.1f} ms"),
    (
        ("typed_stop_latency_ms", "unreachable", "p99"),
        "<=",
        20,
        "typed stop p99 ≤ 20 ms, 10 moving and one robot unreachable",
        "{:.1f} ms",
    ),
    (("registration_s", "100"), "<=", 5, "100 robots registered in ≤ 5 s", "{:.2f} s"),
    (
        ("identification_ms_1200_topics",),
        "<=",
        100,
        "identification of a 1,200-topic robot ≤ 100 ms",
        "{:.2f} ms",
    ),
    (("interpreter_per_s",), ">=", 2000, "interpreter ≥ 2,000 instructions/s", "{:,.0f} /s"),
    (("sim_realtime_robots",), ">=", 500, "simulator ≥ 500 robots at real time", "{:,.0f} robots"),
    (
        ("live_staleness_ms", "p99"),
        "<=",
        200,
        "live staleness p99 ≤ 200 ms, 200 robots, 10 clients",
        "{:.1f} ms",
    ),
    (("success_rate", "no_nav"), ">=", 0.99, "success rate ≥ 99 % without navigation", "{:.3f}"),
    (("success_rate", "nav"), ">=", 0.99, "success rate ≥ 99 % with navigation", "{:.3f}"),
    (("coordination", "32", "contacts"), "<=", 0, "32 robots on crossing routes: 0 contacts", "{:.0f}"),
    (("coordination", "32", "deadlocks"), "<=", 0, "32 robots on crossing routes: 0 deadlocks", "{:.0f}"),
    (
        ("coordination", "32", "completion"),
        ">=",
        1.0,
        "32 robots on crossing routes: every goal reached",
        "{:.3f}",
    ),
    (
        ("coordination", "32", "makespan_ratio"),
        "<=",
        1.5,
        "32 robots: makespan ≤ 1.5 × the longest lone run",
        "{:.2f} ×",
    ),
)


def build_summary(results: dict[str, dict]) -> dict:
    """Merge each experiment's "summary" part into the fixed shape; what nobody measured stays None."""
    summary = {
        "command_latency_ms": {n: {"p50": None, "p99": None} for n in ("1", "10", "100")},
        "direct_latency_ms": {n: {"p50": None, "p99": None} for n in ("1", "10", "100")},
        "relay_latency_ms": {n: {"p50": None, "p99": None} for n in ("1", "10", "100")},
        "stop_latency_ms": {"p50": None, "p99": None, "robots": None, "queued": None},
        "typed_stop_latency_ms": {
            "p50": None,
            "p99": None,
            "robots": None,
            **{
                k: {"p50": None, "p99": None}
                for k in ("unreachable", "one_robot", "socket", "stop_all_button")
            },
            "ratio_p50": None,
        },
        "registration_s": {"1": None, "10": None, "100": None},
        "identification_ms_1200_topics": None,
        "interpreter_per_s": None,
        "sim_realtime_robots": None,
        "live_staleness_ms": {"p50": None, "p99": None, "robots": None, "clients": None},
        "success_rate": {"no_nav": None, "nav": None},
        "coordination": {
            n: {
                "contacts": None,
                "deadlocks": None,
                "completion": None,
                "makespan_s": None,
                "lone_s": None,
                "makespan_ratio": None,
            }
            for n in CROWDS
        },
        "allocation_ms_1000": {"p50": None, "p99": None},
        "stop_faults": None,  # bench/stop_faults.py's table, as it gives it
        "cost_ms_per_s_per_robot": None,  # bench/cost.py: CPU per robot per second of each process kind
    }
    for result in results.values():
        for key, value in (result.get("summary") or {}).items():
            if key not in summary:
                raise ValueError(f"summary: unknown key {key!r} (allowed: {', '.join(SUMMARY_KEYS)})")
            summary[key] = _merge(summary[key], value)
    return summary


def _merge(template, value):
    """Fill a template dict from value without adding keys; scalars replace."""
    if isinstance(template, dict) and isinstance(value, dict):
        return {k: _merge(template[k], value[k]) if k in value else template[k] for k in template}
    return value


def lookup(summary: dict, path: tuple[str, ...]):
    node = summary
    for part in path:
        if not isinstance(node, dict):
            return None
        node = node.get(part)
    return node


def goal_rows(summary: dict) -> list[dict]:
    """Each goal with our value and met / missed / not measured."""
    rows = []
    for path, op, limit, text, reads in GOALS:
        value = lookup(summary, path)
        if value is None:
            verdict, shown = "not measured", "–"
        else:
            verdict = "met" if (value <= limit if op == "<=" else value >= limit) else "MISSED"
            shown = reads.format(value)
        rows.append({"goal": text, "key": ".".join(path), "value": value, "shown": shown, "verdict": verdict})
    return rows


def our_table(table: paper.PaperTable, results: dict[str, dict]) -> dict[tuple[str, str, int], dict]:
    """Our cells for one paper table, keyed like the paper's (section, row label, column)."""
    cells = {}
    for result in results.values():
        for cell in result.get("cells", []):
            if cell["table"] == table.number:
                cells[(cell["section"], cell["row"], cell["column"])] = cell
    return cells


def write_all(results: dict[str, dict], out_dir: Path, mode: str, meta: dict | None = None) -> dict:
    """Write every output file; return the summary."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, result in results.items():
        (out_dir / f"{name}.json").write_text(json.dumps(result, indent=1, default=str) + "\n")
    run = {"mode": mode, "meta": meta or {}, "experiments": list(results)}
    (out_dir / RUN_FILE).write_text(json.dumps(run, indent=1) + "\n")
    return render_all(out_dir)


CLUSTER_REPORT = Path("cluster") / "REPORT.md"


def render_all(out_dir: Path) -> dict:
    """summary.json, the plots and REPORT.md from the run's JSON files in out_dir; return the summary.

    `python -m bench.report DIR` does this alone: a report renderer change needs no new run.
    """
    run = json.loads((out_dir / RUN_FILE).read_text())
    results = {name: json.loads((out_dir / f"{name}.json").read_text()) for name in run["experiments"]}
    summary = build_summary(results)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    plots = write_plots(results, out_dir)
    text = render_markdown(results, summary, run["mode"], plots, run["meta"])
    cluster = out_dir / CLUSTER_REPORT  # the multi-host run's own report (bench.cluster), when one was made
    if cluster.exists():
        text += "\n" + cluster.read_text().replace("](", "](cluster/")
    (out_dir / "REPORT.md").write_text(text)
    return summary


def _fmt(value, digits: int = 3) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def render_headline(summary: dict) -> str:
    """The headline table (goals and our numbers), for REPORT.md and docs/benchmarks.md."""
    lines = ["| goal | ours | verdict |", "|---|---|---|"]
    for row in goal_rows(summary):
        lines.append(f"| {row['goal']} | {row['shown']} | {row['verdict']} |")
    return "\n".join(lines)


def render_latency(summary: dict) -> list[str]:
    """Command issued -> received at the robot's endpoint: the portal against a direct publish, same run."""
    lines = [
        "## Command latency: portal against direct publish (same run)",
        "",
        "| robots moving | direct p50 / p99 (ms) | portal p50 / p99 (ms) | ratio p50 | ratio p99 "
        "| bare relay p50 / p99 (ms) | relay ÷ direct p50 |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in ("1", "10", "100"):
        d, p = summary["direct_latency_ms"][n], summary["command_latency_ms"][n]
        r = summary.get("relay_latency_ms", {}).get(n, {"p50": None, "p99": None})
        ratios = [_fmt(_ratio(p[k], d[k]), 2) for k in ("p50", "p99")]
        lines.append(
            f"| {n} | {_fmt(d['p50'], 2)} / {_fmt(d['p99'], 1)} | {_fmt(p['p50'], 2)} / {_fmt(p['p99'], 1)} | "
            + " | ".join(ratios)
            + f" | {_fmt(r['p50'], 2)} / {_fmt(r['p99'], 1)} | {_fmt(_ratio(r['p50'], d['p50']), 2)} |"
        )
    lines += [
        "",
        "The bare relay (bench/relay.py) is uvicorn with the portal's WebSocket protocol and rosbridge client and "
        "nothing else: what any process between a page and a robot costs with these libraries.",
    ]
    stop = summary["stop_latency_ms"]
    lines += [
        "",
        f"Stop through the portal's WebSocket with {_fmt(stop['queued'])} instructions still queued, "
        f"{_fmt(stop['robots'])} robots moving: stop issued -> zero Twist at each endpoint p50 "
        f"{_fmt(stop['p50'], 1)} ms, p99 {_fmt(stop['p99'], 1)} ms.",
        "",
    ]
    return lines


def _ratio(a, b):
    return a / b if a is not None and b else None


def render_typed_stop(summary: dict, result: dict | None) -> list[str]:
    """A typed stop against the STOP buttons, same run: every kind of stop, with and without an unreachable robot."""
    typed = summary["typed_stop_latency_ms"]
    kinds = (result or {}).get("kinds") or {}
    reachable, unreachable = kinds.get("reachable", {}), kinds.get("unreachable", {})
    socket_p50 = reachable.get("socket", {}).get("p50")
    lines = [
        "## Typed stop: the console against the STOP buttons (same run)",
        "",
        f"Stop issued -> zero Twist received at each robot's endpoint, {_fmt(typed['robots'])} robots turning on "
        "the spot; then the same with one more robot registered whose endpoint accepts TCP and never answers.",
        "",
        "| stop | p50 / p99 (ms) | one robot unreachable: p50 / p99 (ms) | p50 ÷ socket stop p50 | "
        "portal answered, p50 (ms) | stops without a zero / robot not moving |",
        "|---|---|---|---|---|---|",
    ]
    for kind, text in KINDS.items():
        here, there = reachable.get(kind, {}), unreachable.get(kind, {})
        lines.append(
            f"| {text} | {_pair(here)} | {_pair(there)} | {_fmt(_ratio(here.get('p50'), socket_p50), 2)} | "
            f"{_fmt(here.get('answered_ms'), 1)} | {_misses(here)} |"
        )
    worst = [p for p in (typed["p99"], typed["unreachable"]["p99"]) if p is not None]
    verdict = "not measured" if not worst else ("met" if max(worst) <= GOAL_MS else "MISSED")
    lines += [
        "",
        f"Goal: typed stop p99 ≤ {GOAL_MS:g} ms with 10 robots moving, also with an unreachable robot registered: "
        f"**{verdict}** (p99 {_fmt(typed['p99'], 1)} ms; {_fmt(typed['unreachable']['p99'], 1)} ms with the "
        f"unreachable robot). Typed ÷ socket stop at p50: {_fmt(typed['ratio_p50'], 2)}.",
        "",
    ]
    lines += [f"- {note}" for note in (result or {}).get("notes", [])]
    for phase, kinds_here in (("", reachable), (" (unreachable robot registered)", unreachable)):
        first, floor = kinds_here.get("first_typed", {}), kinds_here.get("floor", {})
        if first:
            lines.append(
                f"- warm-up{phase}: the phase's first typed stop, robots idle: p50 {_fmt(first.get('p50'), 1)} ms, "
                f"p99 {_fmt(first.get('p99'), 1)} ms (not in the table)"
            )
        if floor:
            lines.append(
                f'- HTTP floor{phase}: the same POST interpreting "stop" without running it '
                "(POST /api/interpreter/interpret) answered in p50 "
                f"{_fmt(floor.get('answered_ms'), 1)} ms, p99 {_fmt(floor.get('answered_p99_ms'), 1)} ms"
            )
        for kind, stats in kinds_here.items():
            lines += [f"- {kind}{phase} answered: {text}" for text in stats.get("said", [])]
    return [*lines, ""]


def _pair(stats: dict) -> str:
    return f"{_fmt(stats.get('p50'), 1)} / {_fmt(stats.get('p99'), 1)}" if stats else "–"


def _misses(stats: dict) -> str:
    if not stats:
        return "–"
    still = stats.get("stops", 0) - stats.get("moving", 0)
    return f"{stats.get('missing', 0)} / {still} of {stats.get('stops', 0)}"


def render_table(table: paper.PaperTable, results: dict[str, dict]) -> str:
    """The paper's table with 'paper / ours' in every cell, same rows and columns."""
    ours = our_table(table, results)
    head = f"| {table.row_quantity} | " + " | ".join(table.columns) + " |"
    lines = [
        f"**Table {table.number}: {table.title}** (unit: {table.unit}; each cell: paper / ours)",
        "",
        head,
        "|" + "---|" * (len(table.columns) + 1),
    ]
    for section in table.sections:
        lines.append(f"| *{section.name}* |" + " |" * len(table.columns))
        for row in section.rows:
            cells = []
            for i, value in enumerate(row.values):
                cell = ours.get((section.name, row.label, i))
                cells.append(f"{_fmt(value)} / {_fmt(cell['value'] if cell else None)}")
            lines.append(f"| {row.label} | " + " | ".join(cells) + " |")
    notes = list(table.notes) + sorted({c.get("note", "") for c in ours.values()} - {""})
    if notes:
        lines += ["", "Notes: " + "; ".join(notes) + "."]
    return "\n".join(lines)


def render_coordination(summary: dict) -> list[str]:
    """The coordination bench's table: robots sent at once on crossing routes in the warehouse world."""
    rows = summary["coordination"]
    if not any(v is not None for row in rows.values() for v in row.values()):
        return []
    lines = [
        "## Coordination (warehouse world, crossing routes)",
        "",
        "| robots | contacts | deadlocks | completion | makespan (s) | longest lone run (s) | ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    digits = {
        "contacts": 0,
        "deadlocks": 0,
        "completion": 2,
        "makespan_s": 1,
        "lone_s": 1,
        "makespan_ratio": 2,
    }
    for n, row in rows.items():
        lines.append(f"| {n} | " + " | ".join(_fmt(row[k], d) for k, d in digits.items()) + " |")
    alloc = summary["allocation_ms_1000"]
    p50, p99 = _fmt(alloc["p50"], 1), _fmt(alloc["p99"], 1)
    lines += ["", f"Allocation among 1,000 robots: p50 {p50} ms, p99 {p99} ms.", ""]
    return lines


def render_markdown(results: dict[str, dict], summary: dict, mode: str, plots: list[str], meta: dict) -> str:
    parts = [f"# Benchmark report ({mode} run)", ""]
    if meta:
        parts += ["Run: " + ", ".join(f"{k} {v}" for k, v in meta.items()), ""]
    parts += [
        "Medians unless stated; the machine is shared and noisy. `–` means not measured (see Status).",
        "",
        "## Goals",
        "",
        render_headline(summary),
        "",
    ]
    parts += render_latency(summary)
    parts += render_typed_stop(summary, results.get("typed_stop"))
    parts += render_coordination(summary)
    missed = [(n, r["missed"]) for n, r in results.items() if r.get("missed")]
    if missed:
        parts += ["## Goals missed: why", ""] + [f"- **{n}**: {text}" for n, text in missed] + [""]
    parts += ["## Status of each experiment", "", "| experiment | status | why / notes |", "|---|---|---|"]
    for name, result in results.items():
        why = "; ".join(filter(None, [result.get("reason", ""), *result.get("notes", [])]))
        parts.append(f"| {name}: {result.get('title', '')} | {result.get('status', '?')} | {why or '–'} |")
    parts += ["", "## The paper's tables and ours", ""]
    for table in paper.TABLES.values():
        parts += [render_table(table, results), ""]
    profiles = [(n, r["profile"]) for n, r in results.items() if r.get("profile")]
    if profiles:
        parts += ["## Profiles (where the time goes)", ""]
        for name, text in profiles:
            parts += [f"### {name}", "", "```", text.rstrip(), "```", ""]
    if plots:
        parts += ["## Plots", ""] + [f"![{p}]({p})" for p in plots] + [""]
    return "\n".join(parts)


def write_plots(results: dict[str, dict], out_dir: Path) -> list[str]:
    """One PNG per paper table we have cells for, plus the series experiments offer; return the file names."""
    # Deferred: matplotlib takes seconds to import and only the plots need it.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after use("Agg"): pyplot picks its backend when imported

    names = []
    for table in paper.TABLES.values():
        ours = our_table(table, results)
        if not ours:
            continue
        fig = _table_figure(plt, table, ours)
        name = f"table{table.number}.png"
        fig.savefig(out_dir / name, dpi=90)
        plt.close(fig)
        names.append(name)
    coordination = coordination_plot(plt, results, out_dir)
    names += [coordination] if coordination else []
    for result in results.values():
        for series in result.get("series", []):
            fig, ax = plt.subplots(figsize=(6, 4))
            for label, points in series["lines"].items():
                xs, ys = (
                    zip(*[(x, y) for x, y in points if y is not None], strict=True) if points else ((), ())
                )
                ax.plot(xs, ys, marker="o", label=label)
            ax.set(title=series["title"], xlabel=series["x"], ylabel=series["y"])
            if series.get("logx"):
                ax.set_xscale("log", base=2)
            ax.legend()
            ax.grid(alpha=0.3)
            fig.tight_layout()
            fig.savefig(out_dir / series["file"], dpi=90)
            plt.close(fig)
            names.append(series["file"])
    return names


def coordination_plot(plt, results: dict[str, dict], out_dir: Path) -> str | None:
    """Contacts, deadlocks and makespan ratio against the robots sent at once; None without that bench."""
    data = (results.get("component_coordination") or {}).get("component", {}).get("coordination")
    if not data:
        return None
    ns = sorted(data, key=int)
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    for key in ("contacts", "deadlocks"):
        left.plot([int(n) for n in ns], [data[n][key] for n in ns], marker="o", label=key)
    left.set(title="Robot-robot contacts and deadlocks", xlabel="robots", ylabel="count")
    right.plot(
        [int(n) for n in ns], [data[n]["makespan_ratio"] for n in ns], marker="o", label="makespan / lone"
    )
    right.axhline(1.5, color="grey", linestyle="--", label="goal 1.5")
    right.set(title="Makespan against the longest lone run", xlabel="robots", ylabel="ratio")
    for ax in (left, right):
        ax.set_xscale("log", base=2)
        ax.legend()
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "coordination.png", dpi=90)
    plt.close(fig)
    return "coordination.png"


def _table_figure(plt, table: paper.PaperTable, ours: dict):
    """Bars: the paper's value and ours for every cell of the table."""
    labels, theirs, mine = [], [], []
    for section in table.sections:
        for row in section.rows:
            for i, value in enumerate(row.values):
                cell = ours.get((section.name, row.label, i))
                labels.append(f"{section.name.split()[0][:5]} {row.label.split('=')[-1].strip()} c{i + 1}")
                theirs.append(value)
                mine.append(cell["value"] if cell and cell["value"] is not None else 0.0)
    fig, ax = plt.subplots(figsize=(max(6, len(labels) * 0.35), 4))
    xs = range(len(labels))
    ax.bar([x - 0.2 for x in xs], theirs, width=0.4, label="paper")
    ax.bar([x + 0.2 for x in xs], mine, width=0.4, label="ours")
    ax.set_xticks(list(xs), labels, rotation=90, fontsize=6)
    ax.set(title=f"Table {table.number}", ylabel=table.unit)
    ax.legend()
    fig.tight_layout()
    return fig


def main(argv: list[str]) -> int:
    out_dir = Path(argv[0]) if argv else Path(__file__).parent / "results"
    if not (out_dir / RUN_FILE).is_file():
        print(
            f"bench.report: {out_dir} holds no {RUN_FILE}: not a directory bench.run wrote", file=sys.stderr
        )
        return 2
    print(render_headline(render_all(out_dir)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
