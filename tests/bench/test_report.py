"""The report generator on a tiny made-up run: summary shape, side-by-side tables, plots, goal verdicts."""

import json
import subprocess
import sys

import pytest

from bench import report
from experiments.stats import percentile, summarize

TINY = {
    "exp1_direct": {
        "title": "direct publish",
        "status": "ok",
        "cells": [
            {
                "table": 3,
                "section": "StartResponse (s)",
                "row": "ω_z^s = 0.0 rad/s",
                "column": 0,
                "value": 0.123,
            },
        ],
        "summary": {"direct_latency_ms": {"1": {"p50": 1.5, "p99": 3.0}}},
        "series": [
            {
                "title": "t",
                "x": "robots",
                "y": "ms",
                "file": "series.png",
                "logx": True,
                "lines": {"ours": [(1, 1.0), (2, 2.0)]},
            }
        ],
    },
    "interp": {
        "title": "interpreter",
        "status": "ok",
        "summary": {"interpreter_per_s": 1500.0},
        "profile": "ncalls tottime\n 10 0.5 parse",
    },
    "staleness": {"title": "live", "status": "skipped", "reason": "no consumer yet"},
}


def test_summary_has_exactly_the_agreed_keys_and_shape(tmp_path):
    summary = report.write_all(TINY, tmp_path, "quick")
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk == summary
    assert tuple(summary) == report.SUMMARY_KEYS
    assert set(summary["command_latency_ms"]) == {"1", "10", "100"}
    assert set(summary["command_latency_ms"]["1"]) == {"p50", "p99"}
    assert set(summary["stop_latency_ms"]) == {"p50", "p99", "robots", "queued"}
    assert set(summary["live_staleness_ms"]) == {"p50", "p99", "robots", "clients"}
    assert set(summary["success_rate"]) == {"no_nav", "nav"}
    assert summary["direct_latency_ms"]["1"] == {"p50": 1.5, "p99": 3.0}
    assert summary["direct_latency_ms"]["10"] == {"p50": None, "p99": None}
    assert summary["interpreter_per_s"] == 1500.0


def test_each_experiment_gets_its_json_and_the_report_and_plots_exist(tmp_path):
    report.write_all(TINY, tmp_path, "quick")
    for name in TINY:
        assert json.loads((tmp_path / f"{name}.json").read_text())["title"] == TINY[name]["title"]
    text = (tmp_path / "REPORT.md").read_text()
    assert "0.871 / 0.123" in text  # the paper's cell and ours side by side
    assert "0.807 / –" in text
    assert "no consumer yet" in text
    assert "ncalls tottime" in text
    assert (tmp_path / "table3.png").stat().st_size > 0
    assert (tmp_path / "series.png").stat().st_size > 0
    assert not (tmp_path / "table4.png").exists()


def test_goal_verdicts_say_met_missed_or_not_measured(tmp_path):
    summary = report.write_all(TINY, tmp_path, "quick")
    verdicts = {row["key"]: row["verdict"] for row in report.goal_rows(summary)}
    assert verdicts["interpreter_per_s"] == "MISSED"
    assert verdicts["sim_realtime_robots"] == "not measured"
    summary["sim_realtime_robots"] = 800
    assert {r["key"]: r["verdict"] for r in report.goal_rows(summary)}["sim_realtime_robots"] == "met"


def test_goals_read_with_their_units(tmp_path):
    report.write_all(TINY, tmp_path, "quick")
    text = (tmp_path / "REPORT.md").read_text()
    assert "| interpreter ≥ 2,000 instructions/s | 1,500 /s | MISSED |" in text
    assert "| simulator ≥ 500 robots at real time | – | not measured |" in text


def test_the_report_is_rendered_again_from_the_files_alone(tmp_path):
    """`python -m bench.report DIR`: a renderer change re-renders a stored run, in its order, without running it."""
    report.write_all(TINY, tmp_path, "quick", {"seconds": 12})
    first = (tmp_path / "REPORT.md").read_text()
    (tmp_path / "REPORT.md").unlink()
    proc = subprocess.run(
        [sys.executable, "-m", "bench.report", str(tmp_path)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "REPORT.md").read_text() == first
    assert "Run: seconds 12" in first and first.index("exp1_direct:") < first.index("interp:")


def test_rendering_a_directory_no_run_wrote_is_refused_in_words(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    proc = subprocess.run(
        [sys.executable, "-m", "bench.report", str(tmp_path)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    assert f"{tmp_path} holds no run.json" in proc.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]  # nothing written there


def test_a_report_table_has_the_papers_rows_and_columns():
    text = report.render_table(report.paper.TABLE_13, {})
    body = [line for line in text.splitlines() if line.startswith("| ") and "/" in line]
    assert len(body) == 3
    assert all(line.count(" / ") == 4 for line in body)


def test_unknown_summary_key_is_refused():
    with pytest.raises(ValueError, match="unknown key 'speed'"):
        report.build_summary({"x": {"summary": {"speed": 1}}})


def test_percentiles_interpolate_and_refuse_bad_q():
    assert percentile([1, 2, 3, 4], 50) == 2.5
    assert percentile([], 50) is None
    assert summarize([3.0, 1.0, 2.0])["p50"] == 2.0
    with pytest.raises(ValueError, match=r"within 0\.\.100"):
        percentile([1], 101)


def test_the_coordination_bench_gets_its_table_plot_and_goals(tmp_path):
    crowd = {"contacts": 0, "deadlocks": 1, "completion": 1.0, "makespan_s": 90.0, "lone_s": 70.0}
    data = {"coordination": {"32": {**crowd, "makespan_ratio": 1.29, "robots": 32, "failed": {}}}}
    results = {
        "component_coordination": {
            "title": "component bench bench/coordination.py",
            "status": "ok",
            "summary": {
                "coordination": data["coordination"],
                "allocation_ms_1000": {"p50": 12.0, "p99": 30.0},
            },
            "component": data,
        }
    }
    summary = report.write_all(results, tmp_path, "quick")
    assert summary["coordination"]["32"]["makespan_ratio"] == 1.29
    assert summary["coordination"]["2"]["contacts"] is None  # not run: not measured
    text = (tmp_path / "REPORT.md").read_text()
    assert "| 32 | 0 | 1 | 1.00 | 90.0 | 70.0 | 1.29 |" in text
    assert "Allocation among 1,000 robots: p50 12.0 ms, p99 30.0 ms." in text
    assert (tmp_path / "coordination.png").exists()
    verdicts = {row["goal"]: row["verdict"] for row in report.goal_rows(summary)}
    assert verdicts["32 robots on crossing routes: 0 contacts"] == "met"
    assert verdicts["32 robots on crossing routes: 0 deadlocks"] == "MISSED"
