"""Incidents a person must see: a robot stuck, a step failed, a robot offline, an executor lost, a low battery,
an emergency stop, a process hung, odometry refused at the gate (odometry_invalid), Redis or the database
refusing (store_refused), a robot endpoint flooding its links (link_flooding). Raised by the domain (robots,
execution), pushed live to every page, acknowledged and resolved by operators, audited.

    import alerts
    alerts.raise_alert("robot_stuck", robot, "blocked by husky at A", event="execution 42")  # one per event
    alerts.raise_alert("low_battery", robot, "battery at 12%")    # no key: the condition, until it ends
    alerts.resolve_alert("low_battery", robot, "battery at 80%")  # the condition went away by itself

One alert per event: a repeat of the same event counts on its alert (acknowledged or resolved by a person, it is
not shown again); a new event after the old one ended opens a new alert (alerts.service.raise_alert).
"""

# The service is imported when called: Django imports this package (an installed app) before the app registry is
# ready, and the service imports the models.


def raise_alert(kind: str, robot=None, message: str = "", event: str = ""):
    """Raise an alert for a new event (or count a repeat of the same event on its alert); never raises itself."""
    from alerts.service import raise_alert as _raise  # deferred: see the note above

    return _raise(kind, robot, message, event)


def resolve_alert(kind: str, robot=None, note: str = ""):
    """Resolve the open alert of this kind and robot, if any, because its condition ended (no person)."""
    from alerts.service import resolve_open  # deferred: see the note above

    return resolve_open(kind, robot, note)
