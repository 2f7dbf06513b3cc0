"""Ways of commanding robots in a benchmark: straight over rosbridge (the baseline) or through the portal.

Both keep a held command alive at 5 Hz, like a held teleop button (robots stop after 0.5 s without a command).
"""

import asyncio
import json
import time

import live
from experiments.probe import TWIST_TYPE, RobotLink, twist

KEEPALIVE_S = 0.2


class Unavailable(RuntimeError):
    """A part of the system the experiment needs is not there (yet); the message says which."""


class _Held:
    """Re-send the last command per robot until stopped."""

    def __init__(self) -> None:
        self._tasks: dict[str, asyncio.Task] = {}

    def hold(self, key: str, send) -> None:
        self.release(key)

        async def loop():
            while True:
                await asyncio.sleep(KEEPALIVE_S)
                await send()

        self._tasks[key] = asyncio.create_task(loop())

    def release(self, key: str) -> None:
        task = self._tasks.pop(key, None)
        if task is not None:
            task.cancel()

    def release_all(self) -> None:
        for key in list(self._tasks):
            self.release(key)


class DirectDriver:
    """Publish a Twist on the robot's known command topic: the paper's `rostopic pub` (experiment 1)."""

    name = "direct"

    def __init__(self, clients: dict[str, object]) -> None:
        self.clients = clients  # url -> connected RosbridgeClient
        self.held = _Held()

    async def _publish(self, link: RobotLink, linear: float, angular: float) -> None:
        await self.clients[link.url].publish(link.cmd_topic, twist(linear, angular), TWIST_TYPE)

    async def start(self, links: list[RobotLink], linear: float, angular: float) -> float:
        t0 = time.time()
        for link in links:
            await self._publish(link, linear, angular)
            self.held.hold(link.name, lambda lk=link: self._publish(lk, linear, angular))
        return t0

    async def warm_up(self, links: list[RobotLink]) -> None:
        """A zero command to each robot: every link in use before anything is measured."""
        await self.start(links, 0.0, 0.0)
        await asyncio.sleep(0.1)

    async def stop(self, links: list[RobotLink]) -> float:
        t0 = time.time()
        for link in links:
            self.held.release(link.name)
        for link in links:
            await self._publish(link, 0.0, 0.0)
        return t0

    async def close(self) -> None:
        self.held.release_all()


class PortalDriver:
    """The portal's teleop and stop buttons: commands over the page's WebSocket (/ws/fleet/)."""

    name = "portal"

    def __init__(self, ws, robot_ids: dict[str, int]) -> None:
        self.ws = ws  # a connected websockets client, logged in by session cookie
        self.robot_ids = robot_ids
        self.held = _Held()
        self.answered = 0  # the portal's command results so far (its pushes are read and dropped)
        self._reader = asyncio.create_task(self._drain())

    async def _drain(self) -> None:
        """Read everything the portal pushes, so a full socket buffer never holds the commands back."""
        async for raw in self.ws:
            msg = json.loads(raw)
            for one in live.page_messages(msg):
                if one.get("type") == "command.result":  # a burst of presses is answered in one batch
                    self.answered += 1

    async def _send(self, payload: dict) -> None:
        await self.ws.send(json.dumps(payload))

    def _teleop(self, link: RobotLink, linear: float, angular: float) -> dict:
        return {"command": "teleop", "robot": self.robot_ids[link.name], "linear": linear, "angular": angular}

    async def start(self, links: list[RobotLink], linear: float, angular: float) -> float:
        t0 = time.time()
        for link in links:
            payload = self._teleop(link, linear, angular)
            await self._send(payload)
            self.held.hold(link.name, lambda p=payload: self._send(p))
        return t0

    async def warm_up(self, links: list[RobotLink], timeout: float = 10.0) -> None:
        """A zero command to each robot, until the portal answered them all: its links are open and each
        robot's per-press checks are done, as in a portal in use (the first press is not what is measured)."""
        answered = self.answered
        await self.start(links, 0.0, 0.0)
        deadline = time.monotonic() + timeout
        while self.answered < answered + len(links) and time.monotonic() < deadline:
            await asyncio.sleep(0.01)

    async def stop(self, links: list[RobotLink]) -> float:
        t0 = time.time()
        for link in links:
            self.held.release(link.name)
        await self._send({"command": "stop", "robots": [self.robot_ids[link.name] for link in links]})
        return t0

    async def close(self) -> None:
        self.held.release_all()
        self._reader.cancel()
        await self.ws.close()
