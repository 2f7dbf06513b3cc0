"""Where the portal may connect: one canonical URL per robot endpoint, and the allow-list (no Django).

rosbridge has no authentication, so registration is the gate: an admin types an address, and the portal
connects there from inside the network. Before any connection, each URL is parsed, resolved and checked:

- only ws:// and wss:// with a host and a port 1-65535 (80 or 443 when none is given, as WebSocket clients
  connect); no credentials in the URL (they would be stored and shown); at most 255 characters (the column);
- the host must resolve into the allowed networks (FLEET_ROBOT_ALLOWED_NETWORKS: CIDRs, addresses, or host
  names trusted by name; default loopback and the private ranges), so an admin cannot point the portal at an
  arbitrary internal or outside service;
- ws:// endpoints are stored by address: the host is resolved once and the URL rewritten to that address
  (IPv4 first), so what was checked is what the links connect to later (no second DNS answer), and the
  aliases of one endpoint (localhost, 127.0.0.1, 127.1, 0x7f000001, 2130706433) are one robot endpoint.
  [::1] stays its own endpoint: a server may listen on one loopback and not the other. wss:// endpoints keep
  their host name, which TLS verifies, and every address it resolves to must be allowed.

A host that does not resolve is "unreachable", the same word as a closed port (registration words every
failure to reach a rosbridge server the same, so errors never tell which ports are open).
"""

from __future__ import annotations

import asyncio
import ipaddress
import re
import socket
from dataclasses import dataclass
from urllib.parse import urlsplit

from django.conf import settings

from robots.rosbridge.errors import RosbridgeError, UnreachableError

SCHEMES = {"ws": 80, "wss": 443}
MAX_LENGTH = 255  # Robot.endpoint and RegistrationRecord.endpoint
ALLOWED_SETTING = "FLEET_ROBOT_ALLOWED_NETWORKS"
HOST_NAME = re.compile(r"^(?=.{1,253}$)[a-z0-9]([a-z0-9-]*[a-z0-9])?(\.[a-z0-9]([a-z0-9-]*[a-z0-9])?)*$")
Address = ipaddress.IPv4Address | ipaddress.IPv6Address


class EndpointRefused(RosbridgeError):
    """A URL the portal will not connect to (malformed, or outside the allowed networks)."""


@dataclass(frozen=True)
class Parsed:
    """A syntactically valid endpoint URL, before resolution."""

    scheme: str
    host: str  # lower case, without IPv6 brackets
    port: int
    rest: str  # path (no trailing slash) and query

    def url(self, host: str | None = None) -> str:
        shown = host or self.host
        shown = f"[{shown}]" if ":" in shown else shown
        return f"{self.scheme}://{shown}:{self.port}{self.rest}"


@dataclass(frozen=True)
class AllowList:
    """Allowed networks and host names, from the setting's entries."""

    networks: tuple[ipaddress.IPv4Network | ipaddress.IPv6Network, ...]
    names: frozenset[str]

    @classmethod
    def parse(cls, entries) -> AllowList:
        """Entries are CIDRs, addresses or host names; ValueError names a bad one."""
        networks, names = [], set()
        for entry in entries:
            entry = entry.strip().lower()
            try:
                networks.append(ipaddress.ip_network(entry, strict=False))
            except ValueError:
                if not HOST_NAME.match(entry):
                    raise ValueError(f"{entry!r} is neither a network, an address nor a host name") from None
                names.add(entry)
        return cls(tuple(networks), frozenset(names))

    def allows(self, address: Address) -> bool:
        return any(address in network for network in self.networks)


def parse(url: str) -> Parsed:
    """Check a URL's form; EndpointRefused says what is wrong in one line."""
    url = url.strip()
    if len(url) > MAX_LENGTH:
        raise EndpointRefused(f"{url[:60]}...: longer than {MAX_LENGTH} characters")
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:  # a port outside 0-65535, or a malformed IPv6 host
        raise EndpointRefused(f"{url}: not a valid endpoint URL (the port must be 1-65535)") from None
    if parts.scheme not in SCHEMES or not parts.hostname:
        raise EndpointRefused(f"{url}: not a WebSocket URL (expected ws://host:port)")
    if port == 0:
        raise EndpointRefused(f"{url}: not a valid endpoint URL (the port must be 1-65535)")
    if parts.username is not None or parts.password is not None:
        shown = f"{parts.scheme}://…@{parts.netloc.rsplit('@', 1)[1]}"  # never repeat a password
        raise EndpointRefused(f"{shown}: credentials in the URL are not supported")
    rest = parts.path.rstrip("/") + (f"?{parts.query}" if parts.query else "")
    return Parsed(parts.scheme, parts.hostname.lower(), port or SCHEMES[parts.scheme], rest)


async def resolve(url: str, allowed: AllowList, timeout: float = 2.0) -> str:
    """The canonical URL of an endpoint the portal may connect to; EndpointRefused or UnreachableError."""
    parsed = parse(url)
    addresses = await _addresses(parsed, timeout)
    checked = addresses if parsed.scheme == "wss" else addresses[:1]  # ws:// connects to the first only
    refused = next((a for a in checked if not allowed.allows(a)), None)
    if refused is not None and parsed.host not in allowed.names:
        raise EndpointRefused(
            f"{url}: refused: {refused} is outside the allowed robot networks ({ALLOWED_SETTING})"
        )
    return parsed.url(None if parsed.scheme == "wss" else str(addresses[0]))


def check(url: str, allowed: AllowList, timeout: float = 2.0) -> str:
    """resolve() for synchronous callers (a model's clean(), a form)."""
    return asyncio.run(resolve(url, allowed, timeout))


async def _addresses(parsed: Parsed, timeout: float) -> list[Address]:
    """The host's addresses, IPv4 first (the order a ws:// endpoint is stored by)."""
    loop = asyncio.get_running_loop()
    try:
        infos = await asyncio.wait_for(
            loop.getaddrinfo(parsed.host, parsed.port, type=socket.SOCK_STREAM), timeout
        )
    except (OSError, TimeoutError, UnicodeError):
        raise UnreachableError(f"{parsed.url()}: unreachable (the host name does not resolve)") from None
    found = dict.fromkeys(_plain(ipaddress.ip_address(info[4][0].split("%", 1)[0])) for info in infos)
    return sorted(found, key=lambda a: a.version)


def _plain(address: Address) -> Address:
    """An IPv4-mapped IPv6 address (::ffff:10.0.0.1) is the IPv4 address it maps."""
    mapped = getattr(address, "ipv4_mapped", None)
    return mapped if mapped is not None else address


def allow_list() -> AllowList:
    """The networks and hosts robots may be registered from (settings.FLEET_ROBOT_ALLOWED_NETWORKS)."""
    return AllowList.parse(settings.FLEET_ROBOT_ALLOWED_NETWORKS)
