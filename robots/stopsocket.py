"""The running portal's stop line: a unix socket of the links process, which holds a link to every endpoint.

A process with no link up yet (a fresh `manage.py instruct "stop"`) asks here first: the links process publishes
the zeros (CommandSurface.zero) at once on links that are up and answers which robots got them, in a few
milliseconds, where opening links of its own would take the CLI up to a second per robot. Neither side touches
Redis or the database on the way: the links process keeps its robots' command surfaces in memory.

One JSON line each way:

    {"stop": "all"} or {"stop": ["husky", "tiago"]}  ->  {"zeroed": [...], "missed": {name: why}, "unknown": [...]}
    {"status": true}                                  ->  {"up": [names whose link is up], "served": n}

Only the owner may connect: the socket file is 0600 in the portal's var folder (var/proc/stop.sock), and the
server checks the peer's uid as well (SO_PEERCRED). A stop that names a robot it does not know zeroes nothing
(the caller's own interpretation decides), so a misread text never stops the wrong robot.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import socket
import struct
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

from django.conf import settings

log = logging.getLogger(__name__)

ASK_TIMEOUT_S = (
    0.5  # an unanswering portal (hung, stopped) costs the CLI this, then it stops the robots itself
)
MAX_LINE = 64 * 1024

Zero = Callable[[list[str] | str], Awaitable[dict]]


def path() -> Path:
    """settings.FLEET_STOP_SOCKET: var/proc/stop.sock of this portal's var folder (FLEET_VAR_DIR)."""
    return Path(settings.FLEET_STOP_SOCKET)


class StopServer:
    """Answers stop requests with zero(names), and status requests with status(); counts the stops served."""

    def __init__(self, zero: Zero, status: Callable[[], list[str]]) -> None:
        self.zero, self.status = zero, status
        self.served = 0
        self.server: asyncio.AbstractServer | None = None
        self.path: Path | None = None

    async def start(self, where: Path) -> bool:
        """Listen on where (0600); False, logged, when it cannot (a path too long, a read-only folder)."""
        try:
            where.parent.mkdir(parents=True, exist_ok=True)
            with contextlib.suppress(FileNotFoundError):
                where.unlink()  # one links process per var folder (fleet/runguard.py): a file left is stale
            old = os.umask(0o177)
            try:
                self.server = await asyncio.start_unix_server(self._serve, path=str(where), limit=MAX_LINE)
            finally:
                os.umask(old)
            os.chmod(where, 0o600)
        except OSError as exc:
            log.warning("stop socket %s not opened (the CLI stops robots on its own links): %s", where, exc)
            return False
        self.path = where
        log.info("stop socket listening on %s", where)
        return True

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()
        if self.path is not None:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            if _peer_uid(writer) != os.getuid():
                log.warning("stop socket: a connection of another user refused")
                return
            line = await asyncio.wait_for(reader.readline(), ASK_TIMEOUT_S)
            writer.write(json.dumps(await self._answer(json.loads(line))).encode() + b"\n")
            await writer.drain()
        except Exception as exc:  # a bad request or a caller gone: its business, never the links'
            log.info("stop socket: request dropped: %r", exc)
        finally:
            writer.close()

    async def _answer(self, request: dict) -> dict:
        if "stop" not in request:
            return {"up": self.status(), "served": self.served}
        started = time.monotonic()
        names = request["stop"] if request["stop"] == "all" else [str(name) for name in request["stop"]]
        answer = await self.zero(names)
        self.served += 1
        log.info(
            "stop socket: stop %s served in %.1f ms: zeros to %s; missed %s; unknown %s",
            names, (time.monotonic() - started) * 1000, answer["zeroed"], answer["missed"], answer["unknown"],
        )  # fmt: skip
        return answer | {"served": self.served}


def _peer_uid(writer: asyncio.StreamWriter) -> int | None:
    """The connecting process's uid (Linux SO_PEERCRED); None where the platform does not say."""
    sock = writer.get_extra_info("socket")
    try:
        creds = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    except (OSError, AttributeError):
        return None
    return struct.unpack("3i", creds)[1]


def ask(request: dict, where: Path | None = None, timeout: float = ASK_TIMEOUT_S) -> dict | None:
    """One request to the running portal's stop socket; None when there is none or it does not answer in time.

    Blocking and plain (no Redis, no database, no event loop): for a fresh process's first moments."""
    where = where or path()
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(timeout)
            sock.connect(str(where))
            sock.sendall(json.dumps(request).encode() + b"\n")
            return json.loads(_read_line(sock))
    except FileNotFoundError:
        return None  # no portal running on this var folder
    except (OSError, ValueError) as exc:  # refused, unanswering, or a broken answer
        log.info("the portal's stop socket %s did not answer: %r", where, exc)
        return None


def _read_line(sock: socket.socket) -> bytes:
    chunks = []
    while not chunks or not chunks[-1].endswith(b"\n"):
        chunk = sock.recv(MAX_LINE)
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks)


def stop(names: list[str] | str, where: Path | None = None) -> dict | None:
    """Ask the portal to zero these robots ("all": every robot it links); its answer, or None (no portal)."""
    return ask({"stop": names if names == "all" else sorted(names)}, where)
