"""The experiments page's data: the paper's tables beside ours, runs' progress, CSV and JSON exports."""

import csv
import io
import json

import pytest

from experiments import paper, tables
from experiments.models import ExperimentRun

pytestmark = pytest.mark.django_db


def _response_run(user, robot) -> ExperimentRun:
    """A finished response run as runs.execute stores it: one robot's Table 5 cells and summaries."""
    cells = [
        {
            "table": 5,
            "section": "StartResponse (s)",
            "row": "ω_z^s = 0.5 rad/s",
            "column": 1,
            "value": 0.061,
            "n": 3,
        },
        {
            "table": 5,
            "section": "StopResponse (s)",
            "row": "ω_z^e = 0.0 rad/s",
            "column": 0,
            "value": 0.12,
            "n": 3,
        },
    ]
    summary = {"n": 3, "p50": 0.061, "p99": 0.08}
    run = ExperimentRun.objects.create(
        kind="response", user=user, status="succeeded", params={"trials": 3}, total=36, done=36,
        results={"robots": {robot.name: {"cells": cells, "cap": "capped", "start_s": summary, "stop_s": summary}}},
    )  # fmt: skip
    run.robots.set([robot])
    return run


def test_the_last_benchmark_fills_every_paper_table():
    source = tables.bench_source()
    assert source is not None and source.key == "bench"
    compared = tables.compare_all(source.cells)
    assert [t["number"] for t in compared] == list(paper.TABLES)
    goals = sum(slot is not None for slots in paper.SCHEDULE_12.values() for slot in slots)  # FreeTime: none
    for table in compared:
        rows, columns = paper.TABLES[table["number"]].shape()
        expected = goals if table["number"] in (13, 14) else rows * columns
        assert table["measured"] == expected, table["number"]  # as REPORT.md
    table3 = compared[0]
    first = table3["sections"][0]["rows"][0]["cells"][0]
    assert first["paper"] == paper.TABLE_3.value("StartResponse (s)", "ω_z^s = 0.0 rad/s", 0)
    assert first["ours"] is not None


def test_a_missing_benchmark_is_no_source(tmp_path):
    assert tables.bench_source(tmp_path) is None


def test_a_run_shows_beside_table_5_and_exports_as_csv_and_json(client_for, viewer, fleet):
    run = _response_run(viewer, fleet["turtlebot"])
    client = client_for(viewer)
    page = client.get(f"/experiments/?ours=run-{run.pk}-turtlebot").content.decode()
    assert f"run #{run.pk}, turtlebot" in page and "0.061" in page
    assert "{&#x27;" not in page and "pprint" not in page  # no Python dump of the results
    data = client.get(f"/experiments/tables.json?ours=run-{run.pk}-turtlebot").json()
    table5 = next(t for t in data["tables"] if t["number"] == 5)
    assert table5["measured"] == 2 and table5["sections"][0]["rows"][1]["cells"][1]["ours"] == 0.061
    rows = list(csv.DictReader(io.StringIO(client.get(f"/experiments/runs/{run.pk}.csv").content.decode())))
    assert [(r["robot"], r["section"], r["value"]) for r in rows] == [
        ("turtlebot", "StartResponse (s)", "0.061"),
        ("turtlebot", "StopResponse (s)", "0.12"),
    ]
    assert rows[0]["column"] == "U_x^s = 1.0 m/s"
    exported = json.loads(client.get(f"/experiments/runs/{run.pk}.json").content)
    assert exported["results"] == run.results and exported["robots"] == ["turtlebot"]
    comparison = list(
        csv.DictReader(io.StringIO(client.get("/experiments/tables.csv?ours=bench").content.decode()))
    )
    assert len(comparison) == sum(t.shape()[0] * t.shape()[1] for t in paper.TABLES.values())
    assert client.get("/experiments/?ours=run-999-nobody").status_code == 404


def test_status_says_progress_of_the_runs_asked_for(client_for, viewer, fleet):
    run = ExperimentRun.objects.create(kind="success", status="running", total=6, done=2)
    answer = client_for(viewer).get(f"/experiments/status/?ids={run.pk},x,99999").json()
    assert [(r["id"], r["status"], r["done"], r["total"]) for r in answer["runs"]] == [
        (run.pk, "running", 2, 6)
    ]


def test_starting_a_run_counts_its_steps(client_for, operator, fleet, monkeypatch):
    from experiments import runs

    monkeypatch.setattr(runs.run_experiment, "delay", lambda pk: None)
    form = {"kind": "response", "robots": [fleet["turtlebot"].pk], "trials": "2", "confirm": "yes"}
    client_for(operator).post("/experiments/", form)
    run = ExperimentRun.objects.get()
    assert run.total == 2 * len(paper.LINEAR_SPEEDS) * len(paper.ANGULAR_SPEEDS) and run.done == 0
    runs.Progress(run.pk, per_step=2).step()
    run.refresh_from_db()
    assert run.done == 2
