"""The portal's pages: thin views that authorise, ask the domain and render.

Live updates come over the page's WebSocket (fleet/consumers.py); actions go through the JSON API or the
small POST views at the end of this module, which answer JSON to fetch() and redirect plain forms.
"""

import json

from django.conf import settings
from django.contrib import messages
from django.core.paginator import Paginator
from django.http import Http404, HttpResponse, JsonResponse
from django.shortcuts import get_object_or_404, redirect, render

from access import holds, leases
from access.roles import may, requires
from alerts.models import Alert
from audit.models import AuditEntry
from execution import fast_stop
from execution.models import Instruction, Photo, TimeSlot
from fleetcore.world import WorldFormatError, load_world
from places.models import Location, Map
from portal import exports, snapshots
from portal.api_types import MAX_ID, ids_from_text
from portal.consumers import run_command
from robots import sensors
from robots.binding import BindingRefused, choose
from robots.flooding import flooding
from robots.models import Binding, RegistrationRecord, Robot

TIMING_FIELDS = [
    ("interpreted_at", "interpreted"),
    ("dispatched_at", "dispatched"),
    ("first_command_at", "first command"),
    ("motion_started_at", "motion started"),
    ("finished_at", "finished"),
]


def _wants_json(request) -> bool:
    return (
        "application/json" in request.headers.get("Accept", "") or request.content_type == "application/json"
    )


def _payload(request) -> dict:
    if request.content_type == "application/json":
        try:
            data = json.loads(request.body or b"{}")
        except ValueError:
            return {}
        return data if isinstance(data, dict) else {}
    return request.POST.dict()


def _get_robot_for_user(request, pk: int) -> Robot:
    """The robot (the view's @requires mark has already checked that the user may see robots)."""
    return _get_or_404(Robot, pk)


def _get_or_404(model, pk: int):
    """The row, or 404; a key no database can hold is simply not found (SQLite would raise)."""
    if not 1 <= pk <= MAX_ID:
        raise Http404(f"No {model._meta.verbose_name} {pk}.")
    return get_object_or_404(model, pk=pk)


def _map_context() -> dict:
    """The map the dashboard draws, its cells as one character each ('#' occupied, '?' unknown, '.' free)."""
    grid = Map.objects.first()
    if grid is None:
        return {"map": None, "locations": []}
    glyph = {True: "#", False: "."}
    cells = "".join("?" if value < 0 else glyph[value >= 50] for value in grid.cells())
    return {
        "map": {
            "name": grid.name,
            "resolution": grid.resolution,
            "width": grid.width,
            "height": grid.height,
            "origin": [grid.origin_x, grid.origin_y],
            "cells": cells,
        },
        "locations": list(grid.locations.values("id", "name", "x", "y", "kind")),
    }


@requires("view")
def dashboard(request):
    """The fleet at a glance: live map, robots, instruction console."""
    map_data = _map_context()
    rows = snapshots.robot_rows(Robot.objects.all())
    context = {
        "robots": rows,
        "map_data": map_data,
        "locations": map_data["locations"],
        "instructions": Instruction.objects.in_progress_list().select_related("user")[:10],
    }
    return render(request, "fleet/dashboard.html", context)


@requires("view")
def robot_list(request):
    """Every robot with its link, state, current instruction and speed (live)."""
    return render(request, "fleet/robot_list.html", {"robots": snapshots.robot_rows(Robot.objects.all())})


GRAPH_PAGE = 100  # topics, nodes or services per page of a robot's page


# Facts the page shows elsewhere (drive, wheels, legs in "Drive"; the footprint on the map) or only when set.
_FACTS_SHOWN_ELSEWHERE = {"drive", "wheel_count", "leg_count", "footprint"}
_FACT_LABELS = {"urdf_error": "URDF problem", "name": "URDF name", "joint_count": "Joints"}


def _fact_text(value) -> str:
    """A fact as a person reads it: lists joined, numbers rounded, never Python's repr."""
    if isinstance(value, list | tuple):
        return ", ".join(_fact_text(item) for item in value)
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, dict):
        return ", ".join(f"{key} {_fact_text(item)}" for key, item in value.items())
    return str(value)


def _facts(robot) -> list[tuple[str, str]]:
    """The URDF and registration facts of a robot's description worth reading, labelled in words."""
    facts = []
    for key, value in sorted((robot.description or {}).items()):
        if key in _FACTS_SHOWN_ELSEWHERE or value in (None, "", [], {}, 0):
            continue
        label = _FACT_LABELS.get(key, key.replace("_", " ").capitalize())
        facts.append((label, _fact_text(value)))
    return facts


@requires("view")
def robot_detail(request, pk: int):
    """One robot: bindings and how each was found, its ROS graph, URDF facts, history, teleop and lease."""
    robot = _get_robot_for_user(request, pk)
    row = snapshots.robot_rows([robot])[0]
    context = {
        "robot": robot,
        "row": row,
        "bindings": robot.bindings.all(),
        # a robot may list 100,000 topics: the page shows one page of each list, never all of it
        "topics": Paginator(robot.topics.all(), GRAPH_PAGE).get_page(request.GET.get("topics")),
        "nodes": Paginator(robot.nodes.all(), GRAPH_PAGE).get_page(request.GET.get("nodes")),
        "services": Paginator(robot.services.all(), GRAPH_PAGE).get_page(request.GET.get("services")),
        "facts": _facts(robot),
        "feeds": sensors.feeds(robot),
        "diagnostics_stale_s": sensors.DIAGNOSTICS_STALE_S,
        "map_data": _map_context(),
        "transitions": robot.transitions.select_related("instruction")[:30],
        "holds_it": row["holder"] == request.user.username,
        "flooding": flooding(robot.endpoint),
    }
    return render(request, "fleet/robot_detail.html", context)


@requires("view")
def registration(request):
    """Register endpoints and resolve the bindings the engine was unsure of."""
    context = {
        "records": RegistrationRecord.objects.select_related("user")[:20],
        "pending": Binding.objects.filter(needs_user=True).select_related("robot"),
        "demo_endpoints": "\n".join(_simulated_endpoints()),
        "robots": Robot.objects.all(),
    }
    return render(request, "fleet/registration.html", context)


def _simulated_endpoints() -> list[str]:
    """Every endpoint of the simulated world that carries robots, as `make run` serves it (the prefill)."""
    try:
        world = load_world(settings.FLEET_WORLD)
    except (OSError, WorldFormatError):
        return []
    return world.robot_endpoint_urls("127.0.0.1", settings.FLEET_SIM_PORT_BASE)


@requires(POST="edit_bindings")
def choose_binding(request, pk: int):
    """A person picks the topic or service for one action of one robot (a form, so it works without JS)."""
    binding = _get_or_404(Binding, pk)
    target = request.POST.get("target", "")
    if target not in {candidate.get("target") for candidate in binding.candidates}:
        messages.error(request, f"target: {target!r} is not one of the candidates for {binding}.")
        return redirect("registration")
    try:
        chosen = choose(binding.robot, binding.action, target, request.user)
    except BindingRefused as exc:  # a candidate of a type the action cannot use
        messages.error(request, str(exc))
        return redirect("registration")
    messages.success(request, f"{chosen.robot.name}: {chosen.action} now uses {chosen.target}.")
    return redirect("registration")


def _schedule_columns(slots) -> list[tuple]:
    return sorted({(slot.start, slot.end) for slot in slots})


@requires("view")
def schedules(request):
    """Robots × time slots, the shape of the paper's Table 12; admins edit cells in place."""
    slots = list(TimeSlot.objects.select_related("robot", "goal"))
    columns = _schedule_columns(slots)
    cells = {(slot.robot_id, slot.start, slot.end): slot for slot in slots}
    rows = [
        {"robot": robot, "cells": [(start, end, cells.get((robot.pk, start, end))) for start, end in columns]}
        for robot in Robot.objects.all()
    ]
    context = {
        "columns": columns,
        "rows": rows,
        "goals": Location.objects.all(),
        "any_off": any(not slot.enabled for slot in slots),
    }
    return render(request, "fleet/schedules.html", context)


def _filtered_instructions(request):
    rows = Instruction.objects.select_related("user").prefetch_related("robots")
    filters = {key: request.GET.get(key, "").strip() for key in ("status", "type", "user", "robot", "q")}
    lookups = {
        "status": "status",
        "type": "type",
        "user": "user__username",
        "robot": "robots__name",
        "q": "text__icontains",
    }
    for key, lookup in lookups.items():
        if filters[key]:
            rows = rows.filter(**{lookup: filters[key]})
    return rows.distinct(), filters


def _timings(instruction) -> list[dict]:
    """Each stage of an instruction with milliseconds since it was received."""
    stages = []
    for field, label in TIMING_FIELDS:
        moment = getattr(instruction, field)
        if moment is not None:
            elapsed = (moment - instruction.received_at).total_seconds() * 1000
            stages.append({"label": label, "at": moment, "ms": round(elapsed)})
    return stages


@requires("view")
def history(request):
    """Instructions, newest first, with filters and each instruction's timings; ?format=csv|json exports them."""
    rows, filters = _filtered_instructions(request)
    if request.GET.get("format") in exports.FORMATS:
        return exports.response(rows, request.GET["format"])
    page = Paginator(rows, 25).get_page(request.GET.get("page"))
    for instruction in page:
        instruction.timings = _timings(instruction)
    context = {
        "page": page,
        "filters": filters,
        "statuses": Instruction.Status.choices,
        "types": Instruction.Type.choices,
        "robots": Robot.objects.values_list("name", flat=True),
        "query": _query_without_page(request),
    }
    return render(request, "fleet/history.html", context)


@requires("view")
def photo(request, pk: int):
    """A photo a robot took for an instruction (execution.models.Photo), as the image itself."""
    picture = _get_or_404(Photo, pk)
    response = HttpResponse(bytes(picture.image), content_type=picture.content_type)
    response["Cache-Control"] = "private, max-age=86400"  # a photo never changes; only its viewers see it
    return response


def _query_without_page(request) -> str:
    query = request.GET.copy()
    query.pop("page", None)
    query.pop("format", None)
    return query.urlencode()


@requires("read_audit")
def audit(request):
    """Who did what, when: for admins."""
    rows = AuditEntry.objects.select_related("user")
    action, who = request.GET.get("action", "").strip(), request.GET.get("user", "").strip()
    if action:
        rows = rows.filter(action__startswith=action)
    if who:
        rows = rows.filter(user__username=who)
    page = Paginator(rows, 50).get_page(request.GET.get("page"))
    actions = AuditEntry.objects.order_by("action").values_list("action", flat=True).distinct()
    context = {
        "page": page,
        "action": action,
        "who": who,
        "actions": actions,
        "query": _query_without_page(request),
    }
    return render(request, "fleet/audit.html", context)


@requires("view_alerts")
def alerts(request):
    """Incidents: the open ones first, then the resolved ones, newest first; operators act on them here."""
    related = ("robot", "acknowledged_by", "resolved_by")
    resolved = Paginator(Alert.objects.resolved().select_related(*related), 50).get_page(
        request.GET.get("page")
    )
    context = {
        "open_alerts": Alert.objects.open().select_related(*related),
        "page": resolved,
        "can_handle": may(request.user, "handle_alerts"),
    }
    return render(request, "fleet/alerts.html", context)


def _answer(request, ok: bool, detail: str, status: int = 200, **extra):
    """JSON for fetch(), a message and a redirect back for a plain form."""
    if _wants_json(request):
        return JsonResponse({"ok": ok, "detail": detail, **extra}, status=status)
    (messages.success if ok else messages.error)(request, detail)
    return redirect(request.META.get("HTTP_REFERER") or "dashboard")


@requires(POST="control")
def stop(request):
    """The stop button: stop the given robots (or all) that this user may command."""
    payload = _payload(request)
    robots = payload.get("robots", "all")
    if isinstance(robots, str) and robots != "all":
        robots = ids_from_text(robots.split(","))
    if robots == "all" or (isinstance(robots, list) and all(isinstance(pk, int) for pk in robots)):
        fast_stop.stop_blocking(robot_ids=robots)  # flags and zeros first, as the socket's stop does
    reply = run_command(request.user, {"command": "stop", "robots": robots})
    return _answer(request, reply["ok"], reply["detail"], 200 if reply["ok"] else 403)


@requires(POST="control")
def teleop(request, pk: int):
    """Drive a robot at the given speeds (the robot page's buttons, without a WebSocket)."""
    payload = _payload(request)
    content = {"command": "teleop", "robot": pk}
    for field in ("linear", "angular"):
        try:
            content[field] = float(payload.get(field, 0.0))
        except (TypeError, ValueError):
            return _answer(request, False, f"{field}: must be a number", 422)
    reply = run_command(request.user, content)
    return _answer(request, reply["ok"], reply["detail"], 200 if reply["ok"] else 403)


@requires(POST="control")
def release_hold(request, pk: int):
    """Release a robot a person's stop holds (access.holds): the portal may move it again."""
    robot = _get_robot_for_user(request, pk)
    try:
        released = holds.release_by(request.user, [robot])
    except holds.ControlRefused as exc:
        return _answer(request, False, str(exc), 403)
    detail = f"Released {robot.name} ({released[robot.name]})." if released else f"{robot.name} was not held."
    return _answer(request, True, detail, stop_hold=None)


@requires(POST="control")
def lease(request, pk: int):
    """Take, renew or release control of a robot; everyone sees who holds it."""
    robot = _get_robot_for_user(request, pk)
    action = _payload(request).get("action", "take")
    try:
        if action == "release":
            leases.release(request.user, robot)
        elif action == "take":
            leases.take(request.user, robot)
        else:
            return _answer(request, False, "action: must be take or release", 422)
    except leases.ControlRefused as exc:
        return _answer(request, False, str(exc), 403)
    held_by = leases.holder(robot)
    detail = f"{robot.name} is held by {held_by.username}." if held_by else f"{robot.name} is free."
    return _answer(request, True, detail, holder=held_by.username if held_by else None)
