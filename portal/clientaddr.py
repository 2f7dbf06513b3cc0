"""Who is on the other end of a request: the one place that decides a client's address (login throttling).

The peer's address (REMOTE_ADDR) is the client's, unless the peer is one of FLEET_TRUSTED_PROXIES: then the
proxy's X-Forwarded-For is believed, read from the right, and the first address no trusted proxy owns is the
client's. Anyone else's X-Forwarded-For is ignored, so a client cannot rotate it to dodge the lock-out. The web
server must hand the peer through untouched (uvicorn runs with --no-proxy-headers; `fleet/run.py`, `deploy/`).
"""

from __future__ import annotations

import ipaddress
from functools import lru_cache

from django.conf import settings

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


@lru_cache(maxsize=8)
def _networks(entries: tuple[str, ...]) -> tuple[Network, ...]:
    return tuple(ipaddress.ip_network(entry, strict=False) for entry in entries)


def _trusted(address: str, networks: tuple[Network, ...]) -> bool:
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return False
    return any(ip in network for network in networks)


def _valid(address: str) -> bool:
    try:
        ipaddress.ip_address(address)
    except ValueError:
        return False
    return True


def client_address(request) -> str:
    """The client's address (AXES_CLIENT_IP_CALLABLE): the peer's, or what a trusted proxy says it forwarded."""
    peer = request.META.get("REMOTE_ADDR", "")
    networks = _networks(tuple(settings.FLEET_TRUSTED_PROXIES))
    if not _trusted(peer, networks):
        return peer
    hops = [hop.strip() for hop in request.META.get("HTTP_X_FORWARDED_FOR", "").split(",") if hop.strip()]
    for hop in reversed(hops):
        if not _valid(hop):
            return peer  # a proxy that forwards garbage: count the proxy, never a made-up address
        if not _trusted(hop, networks):
            return hop
    return hops[0] if hops else peer
