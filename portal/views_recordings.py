"""Recordings: record the fleet to MCAP from the page (or `manage.py record`), download, replay on a map."""

from pathlib import Path

from django.contrib import messages
from django.db import transaction
from django.http import FileResponse, Http404, JsonResponse
from django.shortcuts import redirect, render

from access.roles import may, requires
from portal.views import _get_or_404, _map_context
from recordings import recorder
from recordings.mcapfile import replay_frames
from recordings.models import Recording
from recordings.tasks import record
from robots.models import Topic

SHOWN = 30


@requires(GET="view", POST="run_experiments")
def recordings(request):
    """GET: the recordings and the form; POST: start one (operators), recorded by a worker."""
    if request.method == "POST":
        return _start(request)
    twists = (
        Topic.objects.filter(type__in=recorder.RAW_TYPES)
        .select_related("robot")
        .order_by("robot__name", "name")
    )
    context = {
        "recordings": Recording.objects.select_related("user")[:SHOWN],
        "raw_choices": [f"{topic.robot.name}:{topic.name}" for topic in twists],
        "can_record": may(request.user, "run_experiments"),
        "max_seconds": recorder.MAX_SECONDS,
    }
    return render(request, "fleet/recordings.html", context)


def _start(request):
    text = request.POST.get("seconds", "").strip()
    try:
        seconds = float(text)
    except ValueError:
        messages.error(request, f"seconds: a number of seconds, got {text[:20]!r}")
        return redirect("recordings")
    try:
        recording = recorder.create(request.user, seconds, request.POST.getlist("raw"))
    except recorder.RecordingError as exc:
        messages.error(request, str(exc))
        return redirect("recordings")
    transaction.on_commit(lambda: record.delay(recording.pk))
    messages.success(request, f"Recording #{recording.pk} started for {seconds:g} s.")
    return redirect("recordings")


def _finished(pk: int) -> Recording:
    recording = _get_or_404(Recording, pk)
    if recording.status != Recording.Status.FINISHED or not Path(recording.path).is_file():
        raise Http404(f"recording {pk} has no file yet ({recording.status})")
    return recording


@requires("view")
def replay(request, pk: int):
    """The recording on the map, with a timeline to scrub through it."""
    recording = _finished(pk)
    return render(request, "fleet/replay.html", {"recording": recording, "map_data": _map_context()})


@requires("view")
def frames(request, pk: int):
    """The recording decoded for the replay page: poses per robot and events, times from its start."""
    return JsonResponse(replay_frames(Path(_finished(pk).path)))


@requires("view")
def download(request, pk: int):
    """The MCAP file itself (opens in Foxglove)."""
    recording = _finished(pk)
    return FileResponse(
        open(recording.path, "rb"), as_attachment=True, filename=f"recording-{recording.pk}.mcap"
    )
