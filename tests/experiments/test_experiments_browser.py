"""The experiments page in a real browser: the paper's tables beside ours, plotted with axes and a legend, and a
run's status and progress followed live until its results appear."""

import threading

import pytest

from experiments import paper
from experiments.models import ExperimentRun

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def _elsewhere(function) -> None:
    """Write from another thread, as the worker would (Playwright's loop owns this one)."""
    thread = threading.Thread(target=function)
    thread.start()
    thread.join(10)


def test_the_paper_tables_render_beside_ours_with_plots(login, viewer, live_url):
    page = login(viewer)
    page.goto(f"{live_url}/experiments/")
    assert page.locator("#conn").count() == 0  # no socket on this page, no pill
    assert page.locator("article.paper-table").count() == len(paper.TABLES)
    table3 = page.locator("#table-3 table.compare")
    header = table3.locator("thead th").all_inner_texts()
    assert header == ["angular speed (rad/s)", *paper.TABLE_3.columns]
    first = table3.locator("tbody tr:not(.section)").first
    assert first.locator("th").inner_text() == "ω_z^s = 0.0 rad/s"
    paper_value, ours = first.locator("td").first.inner_text().split(" / ")
    assert float(paper_value) == paper.TABLE_3.sections[0].rows[0].values[0] and float(ours) > 0
    # one uPlot chart per section, with its axes labelled and a legend naming the paper's and our series
    plots = page.locator("#table-3 .plots .uplot")
    assert plots.count() == 2
    legend = plots.first.locator(".u-legend").inner_text()
    assert "ω_z^s = 0.0 rad/s paper" in legend and "ω_z^s = 0.0 rad/s ours" in legend
    # hovering the first column shows its values in the legend: the paper's 0.871 and ours
    over = plots.first.locator(".u-over")
    box = over.bounding_box()
    page.mouse.move(box["x"] + box["width"] * 0.3 / 2.6, box["y"] + box["height"] / 2)
    page.wait_for_function(
        "el => el.innerText.includes('0.5 m/s')", arg=plots.first.locator(".u-legend").element_handle()
    )
    values = plots.first.locator(".u-legend .u-value").all_inner_texts()
    assert values[0] == "0.5 m/s" and values[1] == "0.871" and float(values[2]) > 0
    # no page-wide horizontal overflow at 1280 px
    assert page.evaluate("document.documentElement.scrollWidth") <= 1280


def test_a_run_status_and_progress_update_live(login, viewer, fleet, live_url):
    run = ExperimentRun.objects.create(kind="success", status="queued", total=4, done=0)
    run.robots.set([fleet["turtlebot"]])
    page = login(viewer)
    page.goto(f"{live_url}/experiments/")
    row = f"#runs tr[data-run='{run.pk}']"
    page.wait_for_selector(f"{row} .status:has-text('queued')")
    _elsewhere(lambda: ExperimentRun.objects.filter(pk=run.pk).update(status="running", done=2))
    page.wait_for_selector(f"{row} .run-count:has-text('2 / 4')")
    assert page.locator(f"{row} .status").inner_text() == "running"
    assert page.locator(f"{row} progress").evaluate("bar => bar.value") == 2
    results = {"goal": "A", "robots": {"turtlebot": {"trials": 4, "succeeded": 3, "rate": 0.75}}}
    _elsewhere(
        lambda: ExperimentRun.objects.filter(pk=run.pk).update(status="succeeded", done=4, results=results)
    )
    page.wait_for_selector(f"{row}[data-status=succeeded] td.run-results:has-text('3 of 4')")
    assert "75 %" in page.locator(f"{row} td.run-results").inner_text()
