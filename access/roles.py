"""Roles: viewer sees, operator instructs and controls robots, admin registers and edits.

The groups carry Django permissions (created by a data migration); views ask permissions, never group names.
"""

VIEWER, OPERATOR, ADMIN = "viewer", "operator", "admin"
ROLES = (VIEWER, OPERATOR, ADMIN)

# What each group may do, as app_label.codename. Each role includes the one before it.
VIEW_PERMS = [
    "robots.view_robot",
    "robots.view_topic",
    "robots.view_node",
    "robots.view_service",
    "robots.view_param",
    "robots.view_binding",
    "robots.view_registrationrecord",
    "places.view_map",
    "places.view_location",
    "execution.view_timeslot",
    "execution.view_instruction",
    "execution.view_execution",
    "robots.view_statetransition",
    "access.view_controllease",
    "experiments.view_experimentrun",
    "alerts.view_alert",
]
OPERATOR_PERMS = [
    *VIEW_PERMS,
    "robots.control_robot",
    "execution.add_instruction",
    "experiments.add_experimentrun",
    "alerts.change_alert",
]
ADMIN_PERMS = [
    *OPERATOR_PERMS,
    "robots.register_robot",
    "robots.add_robot",
    "robots.change_robot",
    "robots.delete_robot",
    "robots.change_binding",
    "execution.edit_schedule",
    "execution.add_timeslot",
    "execution.change_timeslot",
    "execution.delete_timeslot",
    "places.add_location",
    "places.change_location",
    "places.delete_location",
    "places.add_map",
    "places.change_map",
    "audit.view_auditentry",
]
GROUP_PERMS = {VIEWER: VIEW_PERMS, OPERATOR: OPERATOR_PERMS, ADMIN: ADMIN_PERMS}

CONTROL_PERM = "robots.control_robot"
REGISTER_PERM = "robots.register_robot"
SCHEDULE_PERM = "execution.edit_schedule"
AUDIT_PERM = "audit.view_auditentry"
ALERT_VIEW_PERM = "alerts.view_alert"
ALERT_HANDLE_PERM = "alerts.change_alert"  # acknowledge and resolve


def role_of(user) -> str | None:
    """The strongest role a user has, for display."""
    if not user.is_authenticated:
        return None
    if user.is_superuser or user.has_perm(REGISTER_PERM):
        return ADMIN
    if user.has_perm(CONTROL_PERM):
        return OPERATOR
    return VIEWER


def can_control(user) -> bool:
    return user.is_authenticated and user.has_perm(CONTROL_PERM)


def can_register(user) -> bool:
    return user.is_authenticated and user.has_perm(REGISTER_PERM)


def context_processor(request):
    """Expose the user's role and abilities to every template."""
    user = request.user
    return {
        "role": role_of(user),
        "can_control": can_control(user),
        "can_register": can_register(user),
        "can_edit_schedule": user.is_authenticated and user.has_perm(SCHEDULE_PERM),
    }


def sync_groups(apps=None):
    """Create the three groups with their permissions (idempotent)."""
    from django.contrib.auth.models import Group, Permission

    for role, perms in GROUP_PERMS.items():
        group, _ = Group.objects.get_or_create(name=role)
        wanted = []
        for perm in perms:
            app_label, codename = perm.split(".")
            wanted.extend(Permission.objects.filter(content_type__app_label=app_label, codename=codename))
        group.permissions.set(wanted)


def require_perm(request, perm: str) -> None:
    """Refuse an API call (403) unless the user has the permission."""
    from ninja.errors import HttpError

    if not request.user.has_perm(perm):
        raise HttpError(403, f"You do not have permission to do this ({perm}).")
