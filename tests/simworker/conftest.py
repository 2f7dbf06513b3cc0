"""Fixtures for the simulator's tests: a running paper world and a small synchronous rosbridge client."""

import json
import time

import pytest
from websockets.sync.client import connect

from simworker.testing import running_world


class Bridge:
    """A bare rosbridge v2 client over websockets' sync API, for protocol-level tests."""

    def __init__(self, url: str) -> None:
        self.ws = connect(url, max_size=None).__enter__()
        self.count = 0

    def send(self, op: str, **fields) -> None:
        self.ws.send(json.dumps({"op": op, **fields}))

    def recv(self, timeout: float = 5.0) -> dict:
        return json.loads(self.ws.recv(timeout=timeout))

    def call(self, service: str, args: dict | None = None, timeout: float = 5.0) -> dict:
        """Call a service and return the service_response (other messages are skipped)."""
        self.count += 1
        call_id = f"call_service:{service}:{self.count}"
        self.send("call_service", service=service, args=args or {}, id=call_id)
        while True:
            msg = self.recv(timeout)
            if msg.get("op") == "service_response" and msg.get("id") == call_id:
                return msg

    def wait_for(self, predicate, timeout: float = 30.0) -> dict:
        """Return the first message for which predicate(msg) is true."""
        end = time.monotonic() + timeout
        while True:
            msg = self.recv(max(end - time.monotonic(), 0.01))
            if predicate(msg):
                return msg

    def close(self) -> None:
        self.ws.close()


@pytest.fixture
def bridge():
    """Open Bridge clients by URL; all are closed after the test."""
    opened = []

    def open_(url: str) -> Bridge:
        opened.append(Bridge(url))
        return opened[-1]

    yield open_
    for b in opened:
        b.close()


@pytest.fixture(scope="module")
def fast_world():
    """The paper world at 8x real time (navigation tests would otherwise take minutes)."""
    with running_world("paper", time_scale=8.0) as sim:
        yield sim


@pytest.fixture(scope="module")
def world():
    """The paper world at real time."""
    with running_world("paper") as sim:
        yield sim
