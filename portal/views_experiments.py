"""The experiments page: run response-time and success-rate experiments on chosen robots, list and plot runs."""

from django.contrib import messages
from django.shortcuts import redirect, render

from access.roles import may, requires
from experiments.models import ExperimentRun
from experiments.runs import KINDS, ExperimentError, start_run
from portal.api_types import ids_from_text
from robots.models import Robot


@requires(GET="view", POST="run_experiments")
def experiments(request):
    """GET: the form and the last runs; POST: start a run (operators only, with the confirmation ticked)."""
    if request.method == "POST":
        return _start(request)
    runs = ExperimentRun.objects.select_related("user").prefetch_related("robots")[:20]
    return render(
        request,
        "fleet/experiments.html",
        {
            "robots": Robot.objects.all(),
            "kinds": KINDS,
            "runs": runs,
            "can_run": may(request.user, "run_experiments"),
        },
    )


def _start(request):
    ids = ids_from_text(request.POST.getlist("robots"))
    trials = request.POST.get("trials", "3").strip()
    trials = int(trials) if trials.isascii() and trials.isdigit() and len(trials) < 6 else 0
    params = {"trials": trials, "goal": request.POST.get("goal", "A").replace("\x00", "")[:50]}
    try:
        run = start_run(
            request.POST.get("kind", ""),
            Robot.objects.filter(pk__in=ids),
            request.user,
            params,
            confirmed=request.POST.get("confirm") == "yes",
        )
    except ExperimentError as exc:
        messages.error(request, str(exc))
    else:
        messages.success(request, f"Run #{run.pk} ({run.kind}) queued on {len(ids)} robot(s).")
    return redirect("experiments")
