"""execution.held_teleop: a page that went away while its presses were under way costs no error."""

import asyncio
import time

import pytest

from execution.control import GRANT_S, TeleopGrant
from execution.held_teleop import HeldTeleop
from robots.commands import CommandSurface

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(10)]


class Control:
    """The part of execution.control a HeldTeleop uses, recording what was published."""

    GRANT_S = GRANT_S

    def __init__(self) -> None:
        self.published: list[tuple[float, float]] = []

    async def publish_teleop(self, grant, linear, angular):
        self.published.append((linear, angular))
        return linear, angular

    def audit_teleops(self, user, batch) -> None:
        pass

    def link_idle(self, endpoint) -> bool:
        return self.idle

    idle = True

    def teleop_grants(self, robot_ids, user):
        return checks(user, robot_ids)


def checks(user, robot_ids):
    surface = CommandSurface(
        robot_id=7, name="robot7", endpoint="ws://127.0.0.1:1", ros_version=1, move_topic="/cmd_vel"
    )
    return {pk: TeleopGrant(surface, 0.5, 1.0, time.monotonic() + GRANT_S) for pk in robot_ids}


async def test_a_press_answered_on_a_socket_closed_meanwhile_still_goes_out_and_raises_nothing():
    async def closed(reply):  # uvicorn's ClientDisconnected is an OSError
        raise ConnectionResetError("the page went away")

    failures = []
    loop = asyncio.get_running_loop()
    loop.set_exception_handler(lambda _loop, context: failures.append(context))
    control = Control()
    teleop = HeldTeleop(None, closed, checks, control)
    await teleop.take({"robot": 7}, 0.2, 0.0)  # checked first: queued while the checks run
    await teleop.take({"robot": 7}, 0.3, 0.1)  # behind it
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    await teleop.take({"robot": 7}, 0.4, 0.2)  # granted, nothing under way: published at once
    assert control.published[-1] == (0.4, 0.2) and not teleop.chains
    teleop.close()
    assert control.published == [(0.2, 0.0), (0.3, 0.1), (0.4, 0.2)]  # the commands went out in order
    assert failures == []  # no "Task exception was never retrieved"


async def test_a_press_whose_link_is_backed_up_waits_in_its_robots_queue_not_in_the_pages_reading():
    """The page's next frame (a STOP) is read at once: a command its link cannot take now goes in a task."""
    sent = []

    async def answer(reply):
        sent.append(reply)

    control = Control()
    teleop = HeldTeleop(None, answer, checks, control)
    await teleop.take({"robot": 7}, 0.2, 0.0)
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    control.idle = False  # the link is backed up (or connecting)
    await teleop.take({"robot": 7}, 0.3, 0.0)
    assert teleop.chains  # queued, not awaited here
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    teleop.close()
    assert control.published == [(0.2, 0.0), (0.3, 0.0)] and all(r["ok"] for r in sent)
