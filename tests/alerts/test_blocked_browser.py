"""A robot blocked at its goal, seen in a real browser: the step fails with the reason within its deadline, the
alert shows on the dashboard (badge and toast) and an operator acknowledges it (issue 14, "Must show")."""

import math
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from tests.execution.conftest import turtle_sim, turtle_world  # noqa: F401

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(180)]


def elsewhere(function, *args, **kwargs):
    """Call from another thread, as the console's socket does (Playwright's loop owns this one); its result."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(function, *args, **kwargs).result(timeout=60)


def test_a_robot_blocked_at_its_goal_fails_in_time_and_the_operator_acknowledges_the_alert(
    turtle_world,  # noqa: F811
    login,
    operator,
    fleet_admin,
):
    from alerts.models import Alert
    from execution.instructions import submit
    from execution.models import Instruction
    from execution.steps import travel_time
    from fleetcore import motion
    from robots.models import Robot
    from tests.execution.helpers import at_rest, parse, step, wait_for, without_command_timeout

    sim, robot = turtle_world, "turtlebot"
    without_command_timeout(sim, robot)  # at rest must be the executor's doing, not the base's timeout
    start = sim.pose(robot)
    goal = (start[0] + 1.0, start[1])
    sim.call(lambda: sim.fleet.physics.add_fixture(goal[0], goal[1], 0.0, 0.5, 0.5))  # a box the map lacks
    page = login(operator)
    page.wait_for_selector("#conn[data-state=live]")
    page.wait_for_selector("#alerts-badge[data-count='0']")

    instruction = elsewhere(submit, f"move {robot} to X", fleet_admin, parse=parse(step([robot], *goal, "X")))
    row = Robot.objects.get(name=robot)
    limits = motion.Limits(row.max_linear, row.max_angular)
    deadline = travel_time(
        math.dist(start[:2], goal) * 1.5, math.pi, limits.scaled(0.5)
    )  # the step's own limit
    # the dashboard, live: a toast says the step failed and why (the browser is watched while the robot tries)
    page.wait_for_selector(
        f".toast:has-text('instruction #{instruction.pk}: {robot}: stuck on the way to X')",
        timeout=(deadline + 30) * 1000,
    )
    final = Instruction.objects.get(pk=instruction.pk)
    assert final.status == "failed", final.outcome
    assert f"{robot}: stuck on the way to X" in final.outcome and "no progress" in final.outcome
    assert (final.finished_at - final.received_at).total_seconds() < deadline  # failed by the stall, in time
    assert wait_for(lambda: at_rest(sim, robot), timeout=2, what=f"{robot} at rest")
    assert math.dist(sim.pose(robot)[:2], goal) > 0.25  # it never got into the box

    # ... and the badge counts the open alerts: the stall and the failure it ended in are one event, one alert
    failed = Alert.objects.open().get(kind="step_failed", robot__name=robot)
    assert not Alert.objects.open().filter(kind="robot_stuck", robot__name=robot).exists()
    count = Alert.objects.open().count()
    page.wait_for_selector(f"#alerts-badge[data-count='{count}']")

    page.click("#alerts-link")
    alert_row = page.locator(f"#alerts-open tr[data-alert='{failed.pk}']")
    assert (
        f"#{instruction.pk}" in alert_row.inner_text() and "stuck on the way to X" in alert_row.inner_text()
    )
    alert_row.get_by_role("button", name="Acknowledge").click()
    page.wait_for_selector(f"#alerts-open tr[data-alert='{failed.pk}']:has-text('acknowledged by otto')")
    failed.refresh_from_db()
    assert failed.acknowledged_by.username == "otto" and failed.acknowledged_at is not None
    time.sleep(0.5)
    assert math.dist(sim.pose(robot)[:2], goal) > 0.25  # and it stays put
