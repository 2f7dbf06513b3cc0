"""The experiments page: run response-time and success-rate experiments on chosen robots, list and plot runs."""

from django.contrib import messages
from django.core.exceptions import PermissionDenied
from django.shortcuts import redirect, render

from experiments.models import ExperimentRun
from experiments.runs import KINDS, ExperimentError, start_run
from robots.models import Robot

RUN_PERM = "experiments.add_experimentrun"


def experiments(request):
    """GET: the form and the last runs; POST: start a run (operators only, with the confirmation ticked)."""
    if request.method == "POST":
        if not request.user.has_perm(RUN_PERM):
            raise PermissionDenied("You may only view experiments, not run them.")
        return _start(request)
    runs = ExperimentRun.objects.select_related("user").prefetch_related("robots")[:20]
    return render(
        request,
        "fleet/experiments.html",
        {
            "robots": Robot.objects.all(),
            "kinds": KINDS,
            "runs": runs,
            "can_run": request.user.has_perm(RUN_PERM),
        },
    )


def _start(request):
    ids = [int(pk) for pk in request.POST.getlist("robots") if pk.isdigit()]
    try:
        trials = int(request.POST.get("trials", "3"))
    except ValueError:
        trials = 0
    params = {"trials": trials, "goal": request.POST.get("goal", "A")[:50]}
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
