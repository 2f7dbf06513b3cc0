"""The role matrix: who may do what. Every check in the portal asks this module, and nothing else.

Three roles, each including the one before it: a **viewer** sees, an **operator** also instructs and drives
robots, an **admin** also registers robots and edits what everyone relies on (schedules, bindings, places, the
interpreter's seeded words). ``ABILITIES`` is the matrix: one row per ability, the least role that has it, and the
Django permission that carries it. The groups get their permissions from it (``sync_groups``); the API
(``RoleAuth``), the pages (``requires``), the sockets (``portal.consumers.COMMANDS``) and the admin site
(``fleet.admin``) ask ``may(user, ability)``. tests/portal/test_role_matrix.py walks every URL, every API operation
and every socket message type and checks each against this table for anonymous, viewer, operator and admin.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import wraps

from django.contrib.auth.models import Group, Permission
from django.contrib.auth.views import redirect_to_login
from django.core.exceptions import PermissionDenied
from django.http import HttpResponseNotAllowed, JsonResponse
from ninja.errors import HttpError
from ninja.security import SessionAuth

from audit import records as audit

VIEWER, OPERATOR, ADMIN = "viewer", "operator", "admin"
ROLES = (VIEWER, OPERATOR, ADMIN)  # in order: each role has every ability of the ones before it


@dataclass(frozen=True)
class Ability:
    """One row of the matrix: the least role that has it, its Django permission, and what it allows."""

    least: str
    perm: str
    allows: str

    def roles(self) -> tuple[str, ...]:
        return ROLES[ROLES.index(self.least) :]


ABILITIES: dict[str, Ability] = {
    "view": Ability(VIEWER, "robots.view_robot", "see robots, maps, schedules, instructions, experiments"),
    "instruct": Ability(
        OPERATOR, "execution.add_instruction", "give instructions, in words or by clicking the map"
    ),
    "control": Ability(
        OPERATOR, "robots.control_robot", "stop, teleoperate, take and release a control lease"
    ),
    "run_experiments": Ability(OPERATOR, "experiments.add_experimentrun", "start experiment runs on robots"),
    "teach": Ability(
        OPERATOR,
        "interpreter.add_lesson",
        "teach the interpreter a word it does not know yet, and forget a word people taught",
    ),
    "edit_vocabulary": Ability(
        ADMIN, "interpreter.change_synonym", "forget the seeded vocabulary (e.g. 'halt'), edit the ontology"
    ),
    "register": Ability(ADMIN, "robots.register_robot", "register rosbridge endpoints, rename robots"),
    "edit_bindings": Ability(ADMIN, "robots.change_binding", "choose the topic behind a robot's action"),
    "edit_schedules": Ability(ADMIN, "execution.edit_schedule", "create, change and delete time slots"),
    "edit_places": Ability(ADMIN, "places.change_location", "edit maps and locations (Django admin)"),
    "take_over": Ability(ADMIN, "access.change_controllease", "take control of a robot someone else holds"),
    "read_audit": Ability(ADMIN, "audit.view_auditentry", "read the audit trail"),
    "view_alerts": Ability(VIEWER, "alerts.view_alert", "see alerts: the top bar's badge, toasts, /alerts/"),
    "handle_alerts": Ability(OPERATOR, "alerts.change_alert", "acknowledge and resolve alerts"),
}

# What the Django admin shows each role beside its abilities: read access everywhere, edits for admins.
VIEW_MODEL_PERMS = [
    *(f"robots.view_{m}" for m in ("robot", "topic", "node", "service", "param", "binding")),
    "robots.view_registrationrecord",
    *(f"places.view_{m}" for m in ("map", "location")),
    *(f"execution.view_{m}" for m in ("timeslot", "instruction", "execution")),
    "robots.view_statetransition",
    "access.view_controllease",
    "experiments.view_experimentrun",
]
ADMIN_MODEL_PERMS = [
    *(f"robots.{verb}_robot" for verb in ("add", "change", "delete")),
    *(f"execution.{verb}_timeslot" for verb in ("add", "change", "delete")),
    *(f"places.{verb}_location" for verb in ("add", "change", "delete")),
    "places.add_map",
    "places.change_map",
    *(f"interpreter.{verb}_{m}" for verb in ("view", "add", "change", "delete") for m in ("synonym",)),
    *(f"interpreter.{verb}_{m}" for verb in ("view", "add", "change") for m in ("actionconcept",)),
    *(f"interpreter.{verb}_{m}" for verb in ("view", "add", "change") for m in ("destinationconcept",)),
    *(f"interpreter.{verb}_{m}" for verb in ("view", "add", "change") for m in ("destinationclass",)),
    "interpreter.view_lesson",
]


def abilities_of(role: str) -> list[str]:
    """The abilities a role has, in the matrix's order."""
    return [name for name, ability in ABILITIES.items() if role in ability.roles()]


def _group_perms(role: str) -> list[str]:
    extra = ADMIN_MODEL_PERMS if role == ADMIN else []
    return [*VIEW_MODEL_PERMS, *(ABILITIES[name].perm for name in abilities_of(role)), *extra]


GROUP_PERMS = {role: _group_perms(role) for role in ROLES}

# The permissions other modules name directly (kept for them; each is a row above).
CONTROL_PERM = ABILITIES["control"].perm
REGISTER_PERM = ABILITIES["register"].perm
SCHEDULE_PERM = ABILITIES["edit_schedules"].perm
AUDIT_PERM = ABILITIES["read_audit"].perm
ALERT_VIEW_PERM = ABILITIES["view_alerts"].perm
ALERT_HANDLE_PERM = ABILITIES["handle_alerts"].perm


def may(user, ability: str) -> bool:
    """Whether the user has the ability (an unknown ability is a programming error, not a refusal)."""
    perm = ABILITIES[ability].perm
    return bool(user is not None and user.is_authenticated and user.is_active and user.has_perm(perm))


def role_of(user) -> str | None:
    """The strongest role a user has, for display."""
    if not user.is_authenticated:
        return None
    for role in reversed(ROLES):
        if all(may(user, name) for name in abilities_of(role)):
            return role
    return None


def can_control(user) -> bool:
    return may(user, "control")


def can_register(user) -> bool:
    return may(user, "register")


def can_take_over(user) -> bool:
    return may(user, "take_over")


def refusal(user, ability: str) -> str:
    """Why a user is refused, in words: who they are, what they tried, who may."""
    who = getattr(user, "username", "") or "anonymous"
    may_do = " and ".join(f"{role}s" for role in ABILITIES[ability].roles())
    return f"{who} may not {ABILITIES[ability].allows.split(',')[0]}: only {may_do} may ({ability})."


def matrix_markdown() -> str:
    """The matrix as the README's table (a test keeps the README equal to it)."""
    lines = [f"| ability | what it allows | {' | '.join(ROLES)} |", "|---|---|" + ":-:|" * len(ROLES)]
    for name, ability in ABILITIES.items():
        cells = " | ".join("yes" if role in ability.roles() else "—" for role in ROLES)
        lines.append(f"| `{name}` | {ability.allows} | {cells} |")
    return "\n".join(lines)


def context_processor(request):
    """Expose the user's role and abilities to every template (``may.teach``, ``can_control``, ...)."""
    user = request.user
    granted = {name: may(user, name) for name in ABILITIES}
    return {
        "role": role_of(user),
        "may": granted,
        "can_control": granted["control"],
        "can_register": granted["register"],
        "can_edit_schedule": granted["edit_schedules"],
    }


def sync_groups(apps=None):
    """Create the three groups with the permissions the matrix gives them (idempotent)."""
    for role, perms in GROUP_PERMS.items():
        group, _ = Group.objects.get_or_create(name=role)
        wanted = []
        for perm in perms:
            app_label, codename = perm.split(".")
            wanted.extend(Permission.objects.filter(content_type__app_label=app_label, codename=codename))
        group.permissions.set(wanted)


# --- the checks the API and the pages take from the matrix ---------------------------------------------------


def require(request, ability: str) -> None:
    """Refuse an API call (403) unless the user has the ability."""
    if not may(request.user, ability):
        audit_refusal(request, ability)
        raise HttpError(403, refusal(request.user, ability))


SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}


def audit_refusal(request, ability: str) -> None:
    """A refused attempt to change something is audited (who, what, where); refused reads are not."""
    if request.method in SAFE_METHODS:
        return
    audit.record(request.user, "access.refused", request.path[:255], ability=ability, method=request.method)


def _role_auth(ability: str):
    """A django-ninja auth class for one ability, named ``may_<ability>`` so the OpenAPI document lists, per
    operation, which ability it needs (and its security scheme says which roles have it)."""
    if ability not in ABILITIES:
        raise KeyError(f"unknown ability {ability!r}; add it to access.roles.ABILITIES")

    def authenticate(self, request, key):
        """401 for anonymous callers (None), 403 for a role without the ability; before the body is read."""
        if not request.user.is_authenticated:
            return None
        require(request, ability)
        return request.user

    roles = ", ".join(ABILITIES[ability].roles())
    attributes = {
        "ability": ability,
        "openapi_description": f"A logged-in session of: {roles} ({ABILITIES[ability].allows}).",
        "authenticate": authenticate,
        "__doc__": f"Session auth for the {ability!r} ability.",
    }
    return type(f"may_{ability}", (SessionAuth,), attributes)()


_AUTHS: dict[str, object] = {}


def api_auth(ability: str):
    """The django-ninja ``auth=`` of an operation that needs this ability (one instance per ability)."""
    if ability not in _AUTHS:
        _AUTHS[ability] = _role_auth(ability)
    return _AUTHS[ability]


def _wants_json(request) -> bool:
    accept, kind = request.headers.get("Accept", ""), request.content_type or ""
    return "application/json" in accept or kind == "application/json"


def requires(ability: str | None = None, **per_method: str):
    """Mark a page view with the ability each method needs: ``requires("view")`` for a page read with GET,
    ``requires(POST="control")`` for an action, ``requires(GET="view", POST="run_experiments")`` for both.

    Anonymous callers get the login page, a role without the ability 403, another method 405. The marks are
    what the role-matrix test reads: a page without one fails that test.
    """
    needs = {method.upper(): name for method, name in per_method.items()}
    if ability is not None:
        needs.setdefault("GET", ability)
    if "GET" in needs:
        needs.setdefault("HEAD", needs["GET"])
    for name in needs.values():
        if name not in ABILITIES:
            raise KeyError(f"unknown ability {name!r}; add it to access.roles.ABILITIES")

    def decorate(view):
        @wraps(view)
        def wrapper(request, *args, **kwargs):
            wanted = needs.get(request.method)
            if wanted is None:
                return HttpResponseNotAllowed(sorted(needs))
            if not request.user.is_authenticated:
                return redirect_to_login(request.get_full_path())
            if not may(request.user, wanted):
                audit_refusal(request, wanted)
                if _wants_json(request):  # the pages' fetch() calls read the reason from JSON
                    return JsonResponse({"ok": False, "detail": refusal(request.user, wanted)}, status=403)
                raise PermissionDenied(refusal(request.user, wanted))
            return view(request, *args, **kwargs)

        wrapper.abilities = dict(needs)
        return wrapper

    return decorate
