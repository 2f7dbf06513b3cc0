"""Incidents a person must see: a robot stuck, a step failed, a robot offline, an executor lost, a low battery,
an emergency stop. Raised by the domain (robots, execution), pushed live to every page, acknowledged and
resolved by operators, audited.

    import alerts
    alerts.raise_alert("robot_stuck", robot, "blocked by husky at A")   # one open alert per kind and robot
    alerts.resolve_alert("robot_offline", robot, "link up again")        # the condition went away by itself
"""


def raise_alert(kind: str, robot=None, message: str = ""):
    """Raise an alert (or count a repeat of the open one of the same kind and robot); never raises itself."""
    from alerts.service import raise_alert as _raise

    return _raise(kind, robot, message)


def resolve_alert(kind: str, robot=None, note: str = ""):
    """Resolve the open alert of this kind and robot, if any, because its condition ended (no person)."""
    from alerts.service import resolve_open

    return resolve_open(kind, robot, note)
