"""Reading a bench client's WebSocket until the bench says stop."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

POLL_S = 0.5  # how often a client with nothing to read looks at its stop


async def until(ws, stop: asyncio.Event) -> AsyncIterator[tuple[float, str | bytes]]:
    """Each frame the connection receives, with the time it came (time.time()), until `stop` is set."""
    while not stop.is_set():
        try:
            raw = await asyncio.wait_for(ws.recv(), POLL_S)
        except TimeoutError:
            continue
        yield time.time(), raw
