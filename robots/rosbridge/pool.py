"""One rosbridge link per endpoint per event loop: the registry every user of a link goes through.

`await client(url)` returns this loop's RosbridgeClient for url, kept up (reconnecting after restarts), so a
publish is one WebSocket send on the caller's own loop. The portal's WebSocket consumers use it on the web
process's loop; the synchronous facade (robots.rosbridge.sync) wraps the same registry on its loop thread, so a
process has one link per endpoint per loop, whoever asks.
"""

from __future__ import annotations

import asyncio
import weakref

from robots.rosbridge.client import RosbridgeClient
from robots.rosbridge.errors import LinkDown

# A pong later than this drops the link, and every command queued on it. Not the interval (2 s): a web process
# taking a whole fleet's presses at once, on a loaded machine, answered its pings 2 s late and lost its links to
# the shards with the commands on them (1,000 robots, bench.cluster). Whether an endpoint is up is the links
# process's to say (robots.links, a 1 s ping); here a late pong only costs the wait.
PING_TIMEOUT_S = 10.0
_LOOPS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, dict[str, RosbridgeClient]] = (
    weakref.WeakKeyDictionary()
)


async def get(url: str) -> RosbridgeClient:
    """The running loop's client for url, started (it connects in the background), up or not yet."""
    clients = _LOOPS.setdefault(asyncio.get_running_loop(), {})
    link = clients.get(url)
    if link is None:  # set before the first await: concurrent callers share one client
        link = clients[url] = RosbridgeClient(
            url, reconnect=True, ping_interval=2.0, ping_timeout=PING_TIMEOUT_S
        )
        await link.start()
    return link


def idle(url: str) -> bool:
    """Whether the running loop's link to url is up with nothing waiting to be written (RosbridgeClient.idle)."""
    link = _LOOPS.get(asyncio.get_running_loop(), {}).get(url)
    return link is not None and link.idle


async def drop(url: str) -> None:
    """Close the running loop's link to url; the next get() opens a new one."""
    link = _LOOPS.get(asyncio.get_running_loop(), {}).pop(url, None)
    if link is not None:
        await link.close()


async def client(url: str, connect_timeout: float = 2.0) -> RosbridgeClient:
    """The running loop's connected client for url; LinkDown with the reason if it cannot connect in time."""
    link = await get(url)
    if not link.is_connected and not await link.wait_connected(connect_timeout):
        raise LinkDown(f"{url}: not connected ({link.last_error or 'connecting'})")
    return link


async def close_all() -> None:
    """Close the running loop's clients (tests, shutdown)."""
    clients = _LOOPS.pop(asyncio.get_running_loop(), {})
    await asyncio.gather(*(link.close() for link in clients.values()), return_exceptions=True)
