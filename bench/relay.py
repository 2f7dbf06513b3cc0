"""The floor under the portal's hop: a bare relay from a page's WebSocket to a robot's rosbridge link.

The portal puts one process between a page and a robot: a teleop frame is read by uvicorn, checked under its
grant and published on the web process's rosbridge link (execution.held_teleop). How close can that come to a
direct rosbridge publish at all? This relay keeps only the two ends of the hop: uvicorn with the portal's own
WebSocket protocol (fleet.websocket), a bare ASGI app (no Django, no Channels, no checks, no answer), and the
portal's rosbridge client (robots.rosbridge). Each frame names the endpoint and topic itself:
{"url": ..., "topic": ..., "linear": ..., "angular": ...}.

`bench.run --only latency` measures it beside the direct path and the portal: the relay's ratio to the direct
path is what any process in between costs with these libraries; the portal's ratio to the relay is what the
portal adds to that.
"""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
import urllib.request

from experiments.drivers import PortalDriver
from experiments.probe import TWIST_TYPE, twist
from fleet import websocket
from fleetcore import jsontext
from robots.rosbridge import RosbridgeClient


async def app(scope, receive, send) -> None:
    """The ASGI app: a plain HTTP answer (so a starter can tell it is up), and the relaying socket."""
    if scope["type"] == "http":
        await send(
            {"type": "http.response.start", "status": 200, "headers": [(b"content-type", b"text/plain")]}
        )
        await send({"type": "http.response.body", "body": b"relay"})
        return
    if scope["type"] != "websocket":
        return
    await receive()  # websocket.connect
    await send({"type": "websocket.accept"})
    clients: dict[str, RosbridgeClient] = {}
    try:
        while True:
            message = await receive()
            if message["type"] != "websocket.receive":
                return
            frame = jsontext.loads(message.get("text") or message.get("bytes"))
            client = clients.get(frame["url"])
            if client is None:
                client = clients[frame["url"]] = RosbridgeClient(frame["url"], ping_interval=None)
                await client.connect()
            await client.publish(frame["topic"], twist(frame["linear"], frame["angular"]), TWIST_TYPE)
    finally:
        for client in clients.values():
            await client.close()


class RelayDriver(PortalDriver):
    """The portal driver's frames, each carrying its robot's endpoint and topic, to the bare relay."""

    name = "relay"

    def __init__(self, ws, links) -> None:
        super().__init__(ws, {link.name: link.name for link in links})

    def _teleop(self, link, linear: float, angular: float) -> dict:
        return {"url": link.url, "topic": link.cmd_topic, "linear": linear, "angular": angular}

    async def warm_up(self, links, timeout: float = 10.0) -> None:
        """A zero to each robot: the relay's links open before anything is measured (the relay answers
        nothing, so this waits a fixed while)."""
        await self.start(links, 0.0, 0.0)
        await asyncio.sleep(0.5)

    async def stop(self, links) -> float:
        t0 = time.time()
        for link in links:
            self.held.release(link.name)
            await self._send(self._teleop(link, 0.0, 0.0))
        return t0


class Relay:
    """The relay served by uvicorn in a process of its own, as the portal's web is."""

    def __init__(self, port: int, log_path: str) -> None:
        self.port, self.log_path = port, log_path
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> Relay:
        cmd = [sys.executable, "-m", "uvicorn", "bench.relay:app", "--host", "127.0.0.1", "--port", str(self.port),
               "--log-level", "warning", "--no-access-log", *websocket.OPTION]  # fmt: skip
        with open(self.log_path, "ab") as log:
            self.proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the relay exited with {self.proc.returncode} (log: {self.log_path})")
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{self.port}/", timeout=1)
                return self
            except OSError:
                time.sleep(0.1)
        self.__exit__()
        raise RuntimeError(f"the relay did not answer within 20 s (log: {self.log_path})")

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/"
