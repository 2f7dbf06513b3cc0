"""The experiments page's runs carried out on a simulated robot: started from the page, results stored, plotted."""

import pytest
from django.urls import reverse

from experiments.models import ExperimentRun

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow, pytest.mark.usefixtures("eager_celery")]


def _run_from_the_page(client, robot, kind: str, **fields) -> ExperimentRun:
    form = {"kind": kind, "robots": [robot.pk], "trials": "1", "confirm": "yes", **fields}
    response = client.post(reverse("experiments"), form, follow=True)
    assert response.status_code == 200
    return ExperimentRun.objects.get()


def test_a_response_run_times_start_and_stop_over_the_speed_grid(turtle_world, operator, client_for):
    client = client_for(operator)
    run = _run_from_the_page(client, turtle_world.robots["turtlebot"], "response")
    assert run.status == "succeeded", run.results
    measured = run.results["robots"]["turtlebot"]
    assert len(measured["cells"]) == 2 * 3 * 4  # start and stop, the paper's 3 linear x 4 angular speeds
    assert "capped at 0.22 m/s" in measured["cap"]  # the TurtleBot3's own limit, stated
    assert 0 < measured["start_s"]["p50"] < 2.0 and 0 < measured["stop_s"]["p50"] < 2.0
    page = client.get(reverse("experiments")).content.decode()
    assert f'data-results="{run.pk}"' in page  # the run's plot, drawn from its stored results


@pytest.mark.usefixtures("seeded_ontology")
def test_a_success_run_sends_instructions_and_counts_the_arrivals(turtle_world, operator, client_for):
    run = _run_from_the_page(client_for(operator), turtle_world.robots["turtlebot"], "success", goal="A")
    assert run.status == "succeeded", run.results
    assert run.results == {"goal": "A", "robots": {"turtlebot": {"trials": 1, "succeeded": 1, "rate": 1.0}}}
