"""A robot endpoint that floods its links: its robots flagged (a cache entry their page shows) and an alert raised.

robots.rosbridge.inflow drops what an endpoint sends beyond its rate, in whichever process holds the link (web,
workers, links, scheduler), and calls flooded() when the dropping starts, every REPORT_S while it lasts and once
when it ends. The flag and the alert are written from a thread of their own: the link's event loop never waits
for Redis or the database.
"""

from __future__ import annotations

import logging
import threading
import time

from django.core.cache import cache
from django.db import connection

import alerts
from robots.models import Robot

log = logging.getLogger(__name__)
FLAG_TTL_S = 30  # a flag not renewed (the flood ended with its process) lapses


def flag_key(endpoint: str) -> str:
    return f"robots:flooding:{endpoint}"


def flooding(endpoint: str) -> dict | None:
    """{"dropped": frames dropped so far, "at": when last heard (epoch s)} while the endpoint floods; else None."""
    try:
        return cache.get(flag_key(endpoint))
    except Exception:  # Redis away: the page shows the robot without the flag
        log.warning("flood flag of %s not read", endpoint, exc_info=True)
        return None


def flooded(endpoint: str, dropped: int, now_flooding: bool) -> None:
    """An inflow listener (robots.apps registers it): flag and alert, from a thread."""
    threading.Thread(
        target=_record, args=(endpoint, dropped, now_flooding), name="flood flag", daemon=True
    ).start()


def _record(endpoint: str, dropped: int, now_flooding: bool) -> None:
    try:
        if now_flooding:
            cache.set(flag_key(endpoint), {"dropped": dropped, "at": time.time()}, FLAG_TTL_S)
        else:
            cache.delete(flag_key(endpoint))
        for robot in Robot.objects.filter(endpoint=endpoint):
            if now_flooding:
                message = f"{endpoint} sends more frames than its links take; {dropped} dropped so far"
                alerts.raise_alert("link_flooding", robot, message)
            else:
                alerts.resolve_alert("link_flooding", robot, "the endpoint's frames are within bounds again")
    except Exception:
        log.exception("%s: flood flag or alert not recorded", endpoint)
    finally:
        connection.close()
