"""The whole path in a browser: register the demo endpoints, instruct, watch the map, answer a question, stop.

Runs against the other apps (simworker, registration, interpreter, execution); Celery runs tasks eagerly here.
"""

import time

import pytest

from execution.models import Execution
from tests.portal.demo import demo_urls, demo_world, pose_stream

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(180)]

NEAR_A = (
    "() => { const r = [...window.fleet.map.robots.values()].find((r) => r.name === 'turtlebot');"
    " return r && r.pose && Math.hypot(r.pose.x - 2, r.pose.y - 2) < 0.4; }"
)


def test_register_instruct_watch_answer_and_stop(
    seeded_terms, login, fleet_admin, live_url, eager_celery, executor
):
    with demo_world() as world:
        page = login(fleet_admin)
        page.goto(f"{live_url}/register/")
        page.get_by_role("textbox", name="Endpoints").fill("\n".join(demo_urls(world)))
        page.get_by_role("button", name="Register").click()
        page.wait_for_selector("#reg-robots tr:has-text('turtlebot')", timeout=60000)
        for name in ("husky", "tiago", "robot1", "robot4"):
            assert page.locator(f"#reg-robots tr:has-text('{name}')").count() == 1

        with pose_stream():
            page.goto(f"{live_url}/")
            page.wait_for_selector("#conn[data-state=live]")
            page.get_by_label("Instruction", exact=True).fill("move turtlebot to A")
            page.get_by_role("button", name="Send").click()
            try:
                page.wait_for_function(NEAR_A, timeout=90000)
            except Exception:
                robot = "[...window.fleet.map.robots.values()].find((r) => r.name === 'turtlebot')"
                print(
                    "DIAG", page.locator("#parse").inner_text(), page.locator("#progress").inner_text()[:800]
                )
                print("DIAG pose", page.evaluate(f"() => JSON.stringify({robot})"))
                raise
            page.wait_for_selector(".parse:has-text('type I')")

            page.get_by_label("Instruction", exact=True).fill("zoom turtlebot to B")
            page.get_by_role("button", name="Send").click()
            page.wait_for_selector(".parse:has-text('type V') .question")
            page.get_by_label("Your answer").fill("zoom means move")
            page.get_by_role("button", name="Answer").click()
            page.wait_for_selector(".toast:has-text('Learned')")

            page.get_by_role("button", name="STOP ALL").click()
            page.wait_for_selector(".toast:has-text('Stopped')")
            assert "turtlebot" in page.locator(".toast:has-text('Stopped')").first.inner_text()
            # the answered instruction comes back understood, now with a synonym
            page.wait_for_selector(".parse:has-text('type II')", timeout=90000)

            # and a second stop ends it: nothing may still run (in the server's thread) when the world goes away
            page.get_by_role("button", name="STOP ALL").click()
            deadline = time.monotonic() + 30
            while Execution.objects.filter(status__in=("queued", "running")).exists():
                assert time.monotonic() < deadline, "an execution kept running after STOP ALL"
                time.sleep(0.1)
