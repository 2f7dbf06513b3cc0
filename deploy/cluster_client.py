"""What the cluster's test and benchmark see from outside: the portal as a logged-in person, the robots as the
simulator's odometry says they move (never the portal's word for it)."""

from __future__ import annotations

import asyncio
import json
import math
import re
import threading
import time
from dataclasses import dataclass

import requests
import websockets

from deploy.cluster import ADMIN_PASSWORD


class Portal:
    """A logged-in session of the demo admin on one web host (the session is in the shared database, so the
    same cookies work on every web host)."""

    def __init__(self, url: str, session: requests.Session | None = None) -> None:
        self.url = url
        self.session = session or requests.Session()

    def login(self) -> Portal:
        page = self.session.get(f"{self.url}login/", timeout=10).text
        token = re.search(r'name="csrfmiddlewaretoken" value="([^"]+)"', page)[1]
        form = {"username": "admin", "password": ADMIN_PASSWORD, "csrfmiddlewaretoken": token}
        answer = self.session.post(
            f"{self.url}login/", data=form, headers={"Referer": self.url}, allow_redirects=False, timeout=10
        )
        assert answer.status_code == 302, f"login on {self.url} answered {answer.status_code}"
        return self

    def on(self, url: str) -> Portal:
        """The same session (its cookies), asking another web host: what a browser behind a load balancer
        sends when its server is replaced (one host name, so the same cookies)."""
        session = requests.Session()
        for cookie in self.session.cookies:
            session.cookies.set(cookie.name, cookie.value)
        return Portal(url, session)

    def get(self, path: str, timeout: float = 10):
        answer = self.session.get(f"{self.url}api/{path}", timeout=timeout)
        answer.raise_for_status()
        return answer.json()

    def post(self, path: str, body: dict, timeout: float = 30):
        headers = {"X-CSRFToken": self.session.cookies.get("csrftoken", ""), "Referer": self.url}
        answer = self.session.post(f"{self.url}api/{path}", json=body, headers=headers, timeout=timeout)
        assert answer.status_code < 300, f"POST {path}: {answer.status_code} {answer.text[:500]}"
        return answer.json()

    def register(self, urls: list[str], timeout: float = 120) -> list[dict]:
        """Bulk registration as a person does it (queued on a control worker); each endpoint's record once
        finished."""
        records = [ref["record"] for ref in self.post("robots/register", {"endpoints": urls})["records"]]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [self.get(f"robots/registrations/{record}") for record in records]
            if all(record["finished_at"] for record in found):
                return found
            time.sleep(0.2)
        raise TimeoutError(f"registration of {urls} not finished within {timeout:g} s")

    def robots(self) -> dict[str, dict]:
        return {robot["name"]: robot for robot in self.get("robots")}


@dataclass
class Motion:
    x: float = math.nan
    y: float = math.nan
    speed: float = 0.0  # |linear| + |angular| of the last odometry
    at: float = 0.0  # time.monotonic() of the last odometry
    yaw: float = math.nan  # radians, in the odometry's frame


class Odometry:
    """Every robot's odometry, read straight from the simulator shards' rosbridge (a thread of its own)."""

    def __init__(self, shards: dict[str, list[str]], period_ms: int = 100) -> None:
        self.shards = shards  # ws:// URL -> robot names behind it
        self.period_ms = period_ms
        self.motion: dict[str, Motion] = {name: Motion() for names in shards.values() for name in names}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="odometry", daemon=True)

    def __enter__(self) -> Odometry:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5)

    def fresh(self, names, within: float = 1.0) -> bool:
        now = time.monotonic()
        return all(now - self.motion[name].at < within for name in names)

    def at_rest(self, names, speed: float = 0.01, within: float = 1.0) -> bool:
        return self.fresh(names, within) and all(self.motion[name].speed < speed for name in names)

    def moving(self, names, speed: float = 0.02) -> list[str]:
        return [name for name in names if self.motion[name].speed >= speed]

    def _run(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        tasks = [asyncio.create_task(self._follow(url, names)) for url, names in self.shards.items()]
        while not self._stop.is_set():
            await asyncio.sleep(0.1)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    async def _follow(self, url: str, names: list[str]) -> None:
        """Subscribe to the robots' odometry; again whenever the shard comes back."""
        while True:
            try:
                async with websockets.connect(url, max_size=None, open_timeout=3) as ws:
                    for name in names:
                        message = {"op": "subscribe", "topic": f"/{name}/odom", "type": "nav_msgs/Odometry"}
                        await ws.send(json.dumps({**message, "throttle_rate": self.period_ms}))
                    async for raw in ws:
                        self._note(json.loads(raw))
            except (TimeoutError, OSError, websockets.WebSocketException):
                await asyncio.sleep(0.5)

    def _note(self, message: dict) -> None:
        if message.get("op") != "publish":
            return
        name = message["topic"].split("/")[1]
        odometry = message["msg"]
        pose, twist = odometry["pose"]["pose"], odometry["twist"]["twist"]
        position, turn = pose["position"], pose["orientation"]
        speed = math.hypot(twist["linear"]["x"], twist["linear"]["y"]) + abs(twist["angular"]["z"])
        yaw = 2 * math.atan2(turn["z"], turn["w"])  # a planar robot's quaternion
        self.motion[name] = Motion(position["x"], position["y"], speed, time.monotonic(), yaw)
