"""The links process's stop socket (robots/stopsocket.py) and the plain stops a fresh CLI reads before its grammar
(interpreter/quickstop.py)."""

from __future__ import annotations

import asyncio
import socket
import stat
import tempfile
import threading
import time
from pathlib import Path

import pytest

from interpreter.quickstop import stop_subject
from robots import stopsocket


@pytest.fixture
def where():
    return Path(tempfile.mkdtemp(prefix="fleet-stop-")) / "proc" / "stop.sock"


@pytest.fixture
def serving(where):
    """A StopServer on its own loop thread, whose zero records what it was asked and knows husky and tiago."""
    asked = []

    async def zero(names):
        asked.append(names)
        known = {"husky", "tiago"}
        wanted = sorted(known) if names == "all" else names
        unknown = [name for name in wanted if name not in known]
        return {"zeroed": [] if unknown else wanted, "missed": {}, "unknown": unknown}

    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    server = stopsocket.StopServer(zero, lambda: ["husky", "tiago"])
    assert asyncio.run_coroutine_threadsafe(server.start(where), loop).result(5)
    yield asked
    asyncio.run_coroutine_threadsafe(server.close(), loop).result(5)
    loop.call_soon_threadsafe(loop.stop)
    thread.join(5)


def test_a_stop_is_answered_with_the_robots_zeroed_and_counted(serving, where):
    assert stat.S_IMODE(where.stat().st_mode) == 0o600  # the owner's only
    assert stopsocket.stop("all", where)["zeroed"] == ["husky", "tiago"]
    answer = stopsocket.stop(["tiago"], where)
    assert (answer["zeroed"], answer["served"]) == (["tiago"], 2)
    assert stopsocket.stop(["husky", "clock"], where)["unknown"] == ["clock"]
    assert serving == ["all", ["tiago"], ["clock", "husky"]]
    assert stopsocket.ask({"status": True}, where) == {"up": ["husky", "tiago"], "served": 3}


def test_a_stale_socket_file_is_replaced(where):
    where.parent.mkdir(parents=True)
    with socket.socket(socket.AF_UNIX) as left:  # a links process killed -9 left its file behind
        left.bind(str(where))

    async def main():
        server = stopsocket.StopServer(lambda names: None, list)
        assert await server.start(where)
        await server.close()

    asyncio.run(main())
    assert not where.exists()  # and a clean close takes it away


def test_no_portal_or_an_unanswering_one_is_none_within_the_bound(where):
    assert stopsocket.stop("all", where) is None  # no file: no portal on this var folder
    where.parent.mkdir(parents=True)
    with socket.socket(socket.AF_UNIX) as hung:  # listening, never answering (a frozen links process)
        hung.bind(str(where))
        hung.listen()
        started = time.monotonic()
        assert (
            stopsocket.stop(
                "all",
                where,
            )
            is None
        )
        assert time.monotonic() - started < stopsocket.ASK_TIMEOUT_S + 2.0


@pytest.mark.parametrize(
    ("text", "subject"),
    [
        ("stop", "all"),
        ("Stop all robots", "all"),
        ("halt everything", "all"),
        ("stop the whole fleet", "all"),
        ("emergency stop", "all"),
        ("please stop husky and tiago", ["husky", "tiago"]),
        ("freeze, Husky!", ["husky"]),
        ("stop every robot except husky", None),  # the grammar reads what is more than plain
        ("stop husky then move tiago to A", None),
        ("don't stop husky", None),
        ("move husky to A", None),
        ("hold husky for 5 seconds", None),
    ],
)
def test_plain_stops_are_read_with_the_stop_actions_own_words(text, subject):
    assert stop_subject(text) == subject


def test_every_synonym_of_the_stop_action_is_a_plain_stop():
    from fleetcore.actions import ACTIONS

    for phrase in (ACTIONS["stop"].name, *ACTIONS["stop"].synonyms):
        assert stop_subject(f"{phrase} husky") == ["husky"], phrase
