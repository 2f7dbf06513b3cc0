"""live._send_each: a hand-over's pushes go to their groups up to GROUPS_AT_ONCE at a time, each group's in order
(a page reads one group), and a failure pauses the rest as one push's failure does."""

import asyncio

import pytest

import live

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(30)]


class Layer:
    """A channel layer whose group_send waits for a moment, counting the sends under way."""

    def __init__(self, failing: str | None = None) -> None:
        self.sent: list[tuple[str, dict]] = []
        self.in_flight = self.most = 0
        self.failing = failing

    async def group_send(self, group: str, payload: dict) -> None:
        self.in_flight += 1
        self.most = max(self.most, self.in_flight)
        try:
            await asyncio.sleep(0.01)
            if group == self.failing:
                raise ConnectionError("Redis away")
            self.sent.append((group, payload))
        finally:
            self.in_flight -= 1


@pytest.fixture(autouse=True)
def not_quiet(monkeypatch):
    monkeypatch.setattr(live, "_quiet_until", 0.0)


async def test_groups_go_at_once_up_to_the_bound_and_each_groups_pushes_in_order():
    layer = Layer()
    pushes = [(f"robot.{n}", {"n": n, "i": i}) for i in range(3) for n in range(40)]
    await live._send_each(layer, pushes)
    assert sorted(layer.sent, key=repr) == sorted(pushes, key=repr)  # every push, once
    for n in range(40):
        assert [p["i"] for g, p in layer.sent if g == f"robot.{n}"] == [0, 1, 2]
    assert 1 < layer.most <= live.GROUPS_AT_ONCE


async def test_a_failed_send_pauses_the_pushes_not_yet_sent():
    layer = Layer(failing="robot.0")
    pushes = [("robot.0", {"i": 0}), ("robot.0", {"i": 1})] + [(f"robot.{n}", {"i": 0}) for n in range(1, 40)]
    await live._send_each(layer, pushes)
    assert ("robot.0", {"i": 1}) not in layer.sent  # its group's next push is not sent after the failure
    assert len(layer.sent) < len(pushes) - 2  # and the groups after the failed one's batch are skipped
    assert live._quiet_until > 0
