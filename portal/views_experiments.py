"""The experiments page: run response-time and success-rate experiments on chosen robots; the paper's tables
beside ours (the last benchmark's or a run's), plotted; each run's status live, its results exported."""

import csv
import json

from django.contrib import messages
from django.http import Http404, HttpResponse, JsonResponse
from django.shortcuts import redirect, render

from access.roles import may, requires
from experiments import tables
from experiments.models import ExperimentRun
from experiments.runs import KINDS, ExperimentError, start_run
from portal.api_types import MAX_ID, ids_from_text
from robots.models import Robot

RUNS_SHOWN = 20


@requires(GET="view", POST="run_experiments")
def experiments(request):
    """GET: the comparison with the paper, the form and the last runs; POST: start a run (operators only, with
    the confirmation ticked)."""
    if request.method == "POST":
        return _start(request)
    runs = list(ExperimentRun.objects.select_related("user").prefetch_related("robots")[:RUNS_SHOWN])
    sources = _sources(runs)
    chosen = _chosen(request, sources)
    comparisons = tables.compare_all(chosen.cells if chosen else ())
    return render(
        request,
        "fleet/experiments.html",
        {
            "robots": Robot.objects.all(),
            "kinds": KINDS,
            "runs": [{"run": run, "summary": tables.run_summary(run)} for run in runs],
            "can_run": may(request.user, "run_experiments"),
            "sources": sources,
            "chosen": chosen,
            "comparisons": comparisons,
        },
    )


def _sources(runs) -> list[tables.Source]:
    bench = tables.bench_source()
    return ([bench] if bench else []) + tables.run_sources(runs)


def _chosen(request, sources):
    """The source named by ?ours= (the first, the last benchmark, by default); an unknown name is a 404."""
    key = request.GET.get("ours", "")
    if not key:
        return sources[0] if sources else None
    for source in sources:
        if source.key == key:
            return source
    raise Http404(f"ours: no results named {key!r}")


@requires("view")
def tables_export(request, fmt: str):
    """The comparison with the paper, one row per printed cell, as CSV or JSON (?ours= as on the page)."""
    runs = list(ExperimentRun.objects.all()[:RUNS_SHOWN])
    chosen = _chosen(request, _sources(runs))
    comparisons = tables.compare_all(chosen.cells if chosen else ())
    name = f"paper-vs-{chosen.key if chosen else 'nothing'}"
    if fmt == "json":
        body = {"ours": chosen.label if chosen else None, "tables": comparisons}
        return _download(json.dumps(body, indent=1, ensure_ascii=False), f"{name}.json", "application/json")
    return _csv(tables.comparison_rows(comparisons), f"{name}.csv")


@requires("view")
def run_export(request, pk: int, fmt: str):
    """One run: everything stored (JSON) or its measured cells / rates (CSV)."""
    run = _get_run(pk)
    if fmt == "json":
        body = {**run.as_dict(), "params": run.params, "robots": [r.name for r in run.robots.all()]}
        body["results"] = run.results
        return _download(
            json.dumps(body, indent=1, ensure_ascii=False), f"run-{run.pk}.json", "application/json"
        )
    return _csv(tables.run_rows(run), f"run-{run.pk}.csv")


@requires("view")
def runs_status(request):
    """The status and progress of the runs asked for (?ids=1,2), for the page's live updates."""
    ids = ids_from_text(request.GET.get("ids", "").split(","))[:RUNS_SHOWN]
    runs = ExperimentRun.objects.filter(pk__in=ids)
    return JsonResponse({"runs": [run.as_dict() for run in runs]})


def _get_run(pk: int) -> ExperimentRun:
    if pk > MAX_ID:
        raise Http404("no such run")
    try:
        return ExperimentRun.objects.get(pk=pk)
    except ExperimentRun.DoesNotExist:
        raise Http404("no such run") from None


def _download(text: str, filename: str, content_type: str) -> HttpResponse:
    response = HttpResponse(text, content_type=f"{content_type}; charset=utf-8")
    response["Content-Disposition"] = f'attachment; filename="{filename}"'
    return response


def _csv(rows: list[dict], filename: str) -> HttpResponse:
    response = _download("", filename, "text/csv")
    fields = list(dict.fromkeys(key for row in rows for key in row))
    writer = csv.DictWriter(response, fieldnames=fields or ["empty"])
    writer.writeheader()
    writer.writerows(rows)
    return response


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
