"""The watchdog keeps a link to each driven robot's endpoint, so that its zero goes out without a connect."""

import time

import pytest

from execution import watchdog


@pytest.fixture
def opened(monkeypatch):
    """The endpoints get_client was asked for; an endpoint named "ws://down" cannot be reached."""
    asked = []

    def get_client(url):
        asked.append(url)
        if url == "ws://down":
            raise OSError("refused")

    monkeypatch.setattr(watchdog, "get_client", get_client)
    monkeypatch.setattr(watchdog, "_linked", set())
    return asked


def opened_after(asked: list, count: int) -> list:
    """Once `count` opens were asked for and the failed ones forgotten (the watchdog never waits for them)."""
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and (len(asked) < count or "ws://down" in watchdog._linked):
        time.sleep(0.01)
    return sorted(asked)


def test_each_endpoint_is_opened_once_and_one_that_failed_is_tried_again(opened):
    watchdog.keep_links(["ws://a", "", "ws://a", "ws://down"])
    assert opened_after(opened, 2) == ["ws://a", "ws://down"]  # a robot without an endpoint is skipped
    watchdog.keep_links(["ws://a", "ws://down"])
    # ws://a's client keeps its link up by itself; the one that failed is tried again
    assert opened_after(opened, 3) == ["ws://a", "ws://down", "ws://down"]
