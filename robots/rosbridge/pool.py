"""Rosbridge links for code that already runs on an event loop (the portal's WebSocket consumers).

`await client(url)` returns this loop's RosbridgeClient for url, kept up (reconnecting after restarts), so a
publish is one WebSocket send on the caller's own loop: no thread hop, unlike the synchronous facade
(robots.rosbridge.sync) that Django views and Celery tasks use.
"""

from __future__ import annotations

import asyncio
import weakref

from robots.rosbridge.client import RosbridgeClient
from robots.rosbridge.errors import LinkDown

_LOOPS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, dict[str, RosbridgeClient]] = (
    weakref.WeakKeyDictionary()
)


async def client(url: str, connect_timeout: float = 2.0) -> RosbridgeClient:
    """The running loop's connected client for url; LinkDown with the reason if it cannot connect in time."""
    clients = _LOOPS.setdefault(asyncio.get_running_loop(), {})
    link = clients.get(url)
    if link is None:  # set before the first await: concurrent callers share one client
        link = clients[url] = RosbridgeClient(url, reconnect=True, ping_interval=2.0)
        await link.start()
    if not link.is_connected and not await link.wait_connected(connect_timeout):
        raise LinkDown(f"{url}: not connected ({link.last_error or 'connecting'})")
    return link


async def close_all() -> None:
    """Close the running loop's clients (tests, shutdown)."""
    clients = _LOOPS.pop(asyncio.get_running_loop(), {})
    await asyncio.gather(*(link.close() for link in clients.values()), return_exceptions=True)
