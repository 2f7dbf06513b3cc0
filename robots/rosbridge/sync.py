"""Use rosbridge links from synchronous code (Django views, Celery tasks): one event-loop thread per process.

`get_client(url)` returns a thread-safe SyncClient whose RosbridgeClient lives on that loop and keeps its
link up (reconnecting after restarts). The loop and the clients are keyed by process id, so a Celery worker
forked after the parent used a link starts its own (stack-notes: don't connect before the fork).
"""

from __future__ import annotations

import asyncio
import atexit
import contextlib
import os
import threading
from collections.abc import Callable
from functools import cache

from robots.rosbridge import pool
from robots.rosbridge.client import Subscription
from robots.rosbridge.errors import LinkDown


class LoopThread:
    """An asyncio loop running forever in a daemon thread."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name="rosbridge-loop", daemon=True)
        self.thread.start()
        self.clients: dict[str, SyncClient] = {}
        self.lock = threading.Lock()

    def client(self, url: str, connect_timeout: float = 2.0) -> SyncClient:
        """The shared client for url, created on first use; waits for its link outside the lock.

        No lock is held while connecting, so one unreachable endpoint never delays the callers of the others.
        """
        with self.lock:
            client = self.clients.get(url)
            if client is None:
                client = self.clients[url] = SyncClient(self, url)
        client.ensure_connected(connect_timeout)
        return client

    def run(self, coro, timeout: float | None = None):
        """Run a coroutine on the loop and wait for its result."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def stop(self, timeout: float = 5.0) -> None:
        """Close every link, stop the loop and join its thread (an interpreter must not exit under a running loop)."""
        with self.lock:
            clients, self.clients = list(self.clients.values()), {}
        if self.thread.is_alive():
            # on a timeout the loop stops anyway and the sockets close with the process
            with contextlib.suppress(TimeoutError):
                self.run(_close_all(clients), timeout)
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(timeout)
        if not self.thread.is_alive():
            self.loop.close()


class SyncClient:
    """Blocking wrappers over one RosbridgeClient; safe to call from any thread."""

    def __init__(self, runner: LoopThread, url: str) -> None:
        self.runner, self.url = runner, url
        self.client = runner.run(pool.get(url))  # the loop's one link to url; connects in the background

    def _run(self, coro, timeout: float | None = None):
        return self.runner.run(coro, timeout)

    def ensure_connected(self, timeout: float = 2.0) -> None:
        if not self._run(self.client.wait_connected(timeout)):
            raise LinkDown(f"{self.url}: not connected ({self.client.last_error or 'connecting'})")

    def call_service(self, name: str, args: dict | None = None, timeout: float | None = None) -> dict:
        self.ensure_connected()
        return self._run(self.client.call_service(name, args, timeout))

    def publish(self, topic: str, msg: dict, type_: str | None = None) -> None:
        self._run(self.client.publish(topic, msg, type_))

    def advertise(self, topic: str, type_: str) -> None:
        self._run(self.client.advertise(topic, type_))

    def subscribe(self, topic: str, type_: str, callback: Callable[[dict], None], **options) -> Subscription:
        """Subscribe; callback runs on the loop thread, so keep it short and thread-safe."""
        return self._run(self.client.subscribe(topic, type_, callback, **options))

    def unsubscribe(self, sub: Subscription) -> None:
        self._run(self.client.unsubscribe(sub))

    def send_action_goal(self, action: str, action_type: str, goal: dict, on_feedback=None):
        return self._run(self.client.send_action_goal(action, action_type, goal, on_feedback))

    def cancel_action_goal(self, goal) -> None:
        self._run(self.client.cancel_action_goal(goal))

    def close(self) -> None:
        """Close the link; the next get_client(url) opens a new one."""
        with self.runner.lock:
            if self.runner.clients.get(self.url) is self:
                del self.runner.clients[self.url]
        self._run(pool.drop(self.url))


async def _close_all(_clients: list[SyncClient]) -> None:
    """Close the links, then end what else runs on the loop (the WebSockets' keepalives), as asyncio.run would."""
    await pool.close_all()  # the SyncClients' links and any other link opened on this loop (fast stops)
    others = asyncio.all_tasks() - {asyncio.current_task()}
    for task in others:
        task.cancel()
    await asyncio.gather(*others, return_exceptions=True)


@cache
def _runner(pid: int) -> LoopThread:
    atexit.register(_stop_runner, pid)
    return LoopThread()


def _stop_runner(pid: int) -> None:
    if pid == os.getpid():  # a forked child inherits the parent's atexit list, not its loop thread
        shutdown()


def shutdown() -> None:
    """Stop this process's loop thread and close its links; a later get_client() starts afresh."""
    if _runner.cache_info().currsize:
        _runner(os.getpid()).stop()
        _runner.cache_clear()


def get_client(url: str, connect_timeout: float = 2.0) -> SyncClient:
    """Return this process's shared SyncClient for url, connected (LinkDown after connect_timeout)."""
    return _runner(os.getpid()).client(url, connect_timeout)


def run(coro, timeout: float | None = None):
    """Run a coroutine on this process's rosbridge loop thread and wait for its result."""
    return _runner(os.getpid()).run(coro, timeout)
