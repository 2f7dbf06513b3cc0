"""Faults a stop must get through, for the stop-under-fault tests and bench: a Redis of the test's own that can be
frozen (SIGSTOP) or made to refuse writes, the database (SQLite or PostgreSQL) locked by another writer, a robot endpoint that
floods its links (a websockets server in a process of its own), and a hung instructions worker."""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import redis

from fleet import embedded_redis

FLOOD_RATE = 8000  # frames/s the flooding endpoint aims at on each link, as the issue measured


class DedicatedRedis:
    """redis-server on a socket of its own (the test's settings point at it), to freeze or make refuse writes."""

    def __init__(self) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="fr", dir="/tmp"))  # a socket path under 108 characters
        self.socket = self.folder / "redis.sock"
        self.process = embedded_redis.start(self.socket)
        self.url = f"unix://{self.socket}"

    def client(self) -> redis.Redis:
        return redis.Redis(unix_socket_path=str(self.socket), socket_timeout=5)

    def freeze(self) -> None:
        os.kill(self.process.pid, signal.SIGSTOP)

    def thaw(self) -> None:
        os.kill(self.process.pid, signal.SIGCONT)

    def refuse_writes(self) -> None:
        """Every write now fails with NOREPLICAS (no replica is connected), as MISCONF fails them on a full disk."""
        self.client().config_set("min-replicas-to-write", 1)

    def accept_writes(self) -> None:
        self.client().config_set("min-replicas-to-write", 0)

    def close(self) -> None:
        self.thaw()
        embedded_redis.stop(self.process, self.socket)
        shutil.rmtree(self.folder, ignore_errors=True)


class DatabaseLock:
    """Another writer holding the database until released: SQLite's write lock (BEGIN IMMEDIATE), or on
    PostgreSQL an EXCLUSIVE lock on every table (reads go on, every write waits), each from a connection of its
    own. settings: Django's settings_dict of the database (the test database's NAME)."""

    def __init__(self, settings: dict) -> None:
        self.sqlite = settings["ENGINE"].endswith("sqlite3")
        if self.sqlite:
            self.db = sqlite3.connect(
                settings["NAME"], timeout=5, isolation_level=None, check_same_thread=False
            )
        else:
            import psycopg

            self.db = psycopg.connect(
                dbname=settings["NAME"],
                user=settings.get("USER") or None,
                password=settings.get("PASSWORD") or None,
                host=settings.get("HOST") or None,
                port=settings.get("PORT") or None,
                autocommit=True,
                connect_timeout=10,
            )

    def take(self) -> None:
        if self.sqlite:
            self.db.execute("BEGIN IMMEDIATE")
            return
        tables = [
            row[0] for row in self.db.execute("SELECT tablename FROM pg_tables WHERE schemaname = 'public'")
        ]
        self.db.execute("BEGIN")
        self.db.execute(f"LOCK TABLE {', '.join(map(_quoted, tables))} IN EXCLUSIVE MODE")

    def release(self) -> None:
        if self.sqlite:
            held = self.db.in_transaction
        else:
            from psycopg.pq import TransactionStatus

            held = self.db.info.transaction_status != TransactionStatus.IDLE  # in the locks' transaction
        if held:
            self.db.execute("ROLLBACK")

    def close(self) -> None:
        self.release()
        self.db.close()


def _quoted(table: str) -> str:
    return '"' + table.replace('"', '""') + '"'


class Flooder:
    """A robot endpoint (python -m tests.execution.faults PORT) sending ~FLOOD_RATE publish frames a second to
    every client, from a process of its own; it takes whatever it is sent."""

    def __init__(self) -> None:
        from simworker.testing import free_port

        port = free_port()
        self.url = f"ws://127.0.0.1:{port}"
        root = Path(__file__).resolve().parents[2]
        self.process = subprocess.Popen([sys.executable, "-m", "tests.execution.faults", str(port)], cwd=root)
        deadline = time.monotonic() + 15
        while not _listening(port):
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"the flooding endpoint did not start on {self.url}")
            time.sleep(0.05)

    def close(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(5)


def _listening(port: int) -> bool:
    import socket

    with socket.socket() as sock:
        return sock.connect_ex(("127.0.0.1", port)) == 0


async def _flood(ws) -> None:
    """Publish frames at FLOOD_RATE (in batches every 10 ms) until the client goes; read and drop what it sends."""
    import asyncio
    import json

    frame = json.dumps({"op": "publish", "topic": "/odom", "msg": {"flood": "x" * 64}})
    drain = asyncio.ensure_future(_drain(ws))
    try:
        while True:
            for _ in range(FLOOD_RATE // 100):
                await ws.send(frame)
            await asyncio.sleep(0.01)
    finally:
        drain.cancel()


async def _drain(ws) -> None:
    async for _ in ws:
        pass


def main(port: int) -> None:
    import asyncio

    from websockets.asyncio.server import serve

    async def run():
        async with serve(_flood, "127.0.0.1", port, compression=None, max_queue=None):
            await asyncio.Future()

    asyncio.run(run())


if __name__ == "__main__":
    main(int(sys.argv[1]))
