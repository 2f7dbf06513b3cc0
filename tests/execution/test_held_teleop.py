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


async def test_a_press_read_after_a_stop_waits_for_its_bookkeeping_then_is_checked_anew():
    """The page's STOP runs its bookkeeping beside the socket's frames (portal.consumers): a press read meanwhile is
    not published under the grant it had, but checked once the bookkeeping is done."""
    sent, events = [], []

    async def answer(reply):
        sent.append(reply)

    def counted(user, robot_ids):
        events.append("checked")
        return checks(user, robot_ids)

    control = Control()
    teleop = HeldTeleop(None, answer, counted, control)
    await teleop.take({"robot": 7}, 0.2, 0.0)
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    assert control.published == [(0.2, 0.0)] and events == ["checked"]

    async def bookkeeping():  # control.stop: flags, second zeros, the hold
        await asyncio.sleep(0.2)
        events.append("stop done")

    teleop.stopped([7], asyncio.ensure_future(bookkeeping()))
    await teleop.take({"robot": 7}, 0.3, 0.0)  # a press after the STOP
    assert control.published == [(0.2, 0.0)] and teleop.chains  # not under the old grant: waiting
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    assert events == ["checked", "stop done", "checked"] and control.published == [(0.2, 0.0), (0.3, 0.0)]
    teleop.close()


async def test_a_pages_first_press_after_its_stop_waits_for_that_stops_bookkeeping():
    """The page's HeldTeleop is made at its first press; a STOP the page sent before it (its bookkeeping still under
    way) is in the page's set of stops, which the HeldTeleop shares: the first press is checked after it."""
    events = []

    async def answer(reply):
        events.append("answered")

    def counted(user, robot_ids):
        events.append("checked")
        return checks(user, robot_ids)

    async def bookkeeping():
        await asyncio.sleep(0.2)
        events.append("stop done")

    page_stops = {asyncio.ensure_future(bookkeeping())}  # the page socket's stops_running
    teleop = HeldTeleop(None, answer, counted, Control(), page_stops)
    await teleop.take({"robot": 7}, 0.2, 0.0)
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    assert events == ["stop done", "checked", "answered"]
    teleop.close()


async def test_commands_sent_before_a_stop_and_not_out_yet_are_not_sent_after_it():
    sent, checking, proceed = [], asyncio.Event(), asyncio.Event()

    async def answer(reply):
        sent.append(reply)

    control = Control()
    teleop = HeldTeleop(None, answer, checks, control)
    slow_check = teleop._check

    async def check(robot_id):  # the checks' thread still running when the STOP is read
        checking.set()
        await proceed.wait()
        return await slow_check(robot_id)

    teleop._check = check
    await teleop.take({"robot": 7}, 0.2, 0.0)
    await teleop.take({"robot": 7}, 0.3, 0.0)  # queued behind it
    await asyncio.wait_for(checking.wait(), 5)
    teleop.stopped("all", asyncio.ensure_future(asyncio.sleep(0)))
    proceed.set()
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    assert control.published == []
    assert [r["ok"] for r in sent] == [False, False]
    assert all("stopped after this command was sent" in r["detail"] for r in sent)
    teleop.close()


async def test_a_burst_of_presses_is_published_before_any_answer_and_answered_in_one_frame_in_order():
    """The next robot's command does not wait behind the last one's answer (its encoding, compression, write)."""
    events = []

    async def answer(frame):
        events.append(("answer", frame))

    control = Control()
    real_publish = control.publish_teleop

    async def publish_teleop(grant, linear, angular):
        events.append(("publish", linear))
        return await real_publish(grant, linear, angular)

    control.publish_teleop = publish_teleop
    teleop = HeldTeleop(None, answer, checks, control)
    await teleop.take({"robot": 7, "ref": 0}, 0.1, 0.0)  # the first press: checked, then granted
    await asyncio.wait_for(asyncio.gather(*teleop.chains.values()), 5)
    await asyncio.sleep(0.01)
    events.clear()
    for ref, linear in enumerate(
        (0.2, 0.3, 0.4), start=1
    ):  # three frames read in one go: no turn of the loop
        await teleop.take({"robot": 7, "ref": ref}, linear, 0.0)
    assert events == [("publish", 0.2), ("publish", 0.3), ("publish", 0.4)]  # out, not answered yet
    await asyncio.wait_for(teleop.answering, 5)
    ((kind, frame),) = events[3:]
    assert kind == "answer" and frame["type"] == "batch"
    assert [(m["ref"], m["ok"], m["detail"]) for m in frame["messages"]] == [
        (1, True, "robot7: linear 0.20 m/s, angular 0.00 rad/s"),
        (2, True, "robot7: linear 0.30 m/s, angular 0.00 rad/s"),
        (3, True, "robot7: linear 0.40 m/s, angular 0.00 rad/s"),
    ]
    await teleop.take({"robot": 7, "ref": 4}, 0.5, 0.0)  # a press on its own is answered on its own
    await asyncio.wait_for(teleop.answering, 5)
    kind, alone = events[-1]
    assert kind == "answer" and alone["type"] == "command.result"
    assert (alone["ref"], alone["ok"], alone["detail"]) == (
        4,
        True,
        "robot7: linear 0.50 m/s, angular 0.00 rad/s",
    )
    teleop.close()
