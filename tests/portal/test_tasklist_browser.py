"""The operator's day in a browser, against the simulated paper world: two instructions queued for husky show in
the task list (the running one with its step, the distance left and an ETA; the other queued behind it), both are
cancelled from the page (the queued one first), husky comes to rest (its simulated odometry says so), History
shows both cancelled and the CSV export carries them. The same flow through the API alone follows."""

import csv
import io
import math
import time

import pytest

from execution.models import Instruction, TimeSlot
from tests.execution.helpers import wait_for
from tests.portal.test_telemetry_browser import registered_world

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(240)]

FAR = (
    "move husky to Room 2",
    "move husky to Room 3",
)  # about 8 m from where husky starts: long enough to watch


def at_rest(world, name: str = "husky", window_s: float = 1.0, within_m: float = 0.01) -> bool:
    """The simulator's odometry moved less than within_m (and turned less than a degree) over window_s."""
    before = world.pose(name)
    time.sleep(window_s)
    after = world.pose(name)
    turned = abs(math.remainder(after[2] - before[2], math.tau))
    return math.dist(before[:2], after[:2]) < within_m and turned < math.radians(1)


def moving(world, name: str = "husky") -> bool:
    return not at_rest(world, name, window_s=0.5, within_m=0.02)


def free_of_slots():
    """The paper world's schedules would keep husky for its slot at some hours of the day: not in this test."""
    TimeSlot.objects.all().delete()


@pytest.fixture
def runs_in_threads(settings, eager_celery, transactional_db):
    """The executor on a loop of the test process, as its own process would run it: the page's socket answers at
    once, so a second instruction can queue behind the first."""
    from execution import executor

    with executor.in_thread() as running:
        yield running


def csv_rows(text: str) -> dict[int, dict]:
    return {int(row["id"]): row for row in csv.DictReader(io.StringIO(text))}


def test_an_operator_queues_two_moves_watches_them_and_cancels_both_from_the_page(
    seeded_terms, login, operator, fleet_admin, live_url, runs_in_threads
):
    with registered_world(fleet_admin, keys=("husky",)) as world:
        free_of_slots()
        page = login(operator)
        page.goto(f"{live_url}/")
        page.wait_for_selector("#conn[data-state=live]")
        box = page.get_by_label("Instruction", exact=True)
        for text in FAR:
            box.fill(text)
            page.get_by_role("button", name="Send").click()
            page.wait_for_selector(f"#tasklist li:has-text('{text}')", timeout=30000)

        first, second = (Instruction.objects.get(text=text) for text in FAR)
        running = page.locator(f"#tasklist li[data-task-instruction='{first.pk}']")
        queued = page.locator(f"#tasklist li[data-task-instruction='{second.pk}']")
        running.filter(has_text="step 1 of 1").wait_for()
        page.wait_for_function(
            "(id) => /\\d+\\.\\d m left · ETA \\d+ s/.test("
            "document.querySelector(`[data-progress='${id}']`)?.textContent || '')",
            arg=first.pk,
        )
        queued.filter(has_text="queued 1").wait_for()
        assert wait_for(lambda: moving(world), 30, "husky drives towards Room 2")

        queued.get_by_role("button", name=f"Cancel #{second.pk}").click()
        page.wait_for_selector(f"#tasklist li[data-task-instruction='{second.pk}']", state="detached")
        assert moving(world), "cancelling the queued instruction left the running one alone"
        running.get_by_role("button", name=f"Cancel #{first.pk}").click()
        page.wait_for_selector(f"#tasklist li[data-task-instruction='{first.pk}']", state="detached")
        wait_for(lambda: at_rest(world), 15, "husky at rest after its instruction was cancelled")
        page.wait_for_selector("#tasklist:has-text('Nothing running or queued')")

        page.goto(f"{live_url}/history/?robot=husky")
        for instruction in (first, second):
            row = page.locator("#history tbody tr", has_text=instruction.text)
            assert row.locator(".badge").inner_text() == "cancelled"
            assert "cancelled by otto" in row.inner_text()
        exported = page.request.get(f"{live_url}/history/?robot=husky&format=csv")
        assert exported.ok and exported.headers["content-type"].startswith("text/csv")
        rows = csv_rows(exported.text())
        for instruction in (first, second):
            assert rows[instruction.pk]["status"] == "cancelled"
            assert rows[instruction.pk]["robots"] == "husky"
            assert rows[instruction.pk]["user"] == "otto"
        assert at_rest(world), "husky stayed at rest"


def test_the_same_flow_through_the_api_alone(
    seeded_terms, login, operator, viewer, fleet_admin, live_url, runs_in_threads
):
    """No page: instruct, read the queue, refuse a viewer each call, cancel both, export; Playwright's request
    context is the API client (a session cookie from the login form, the CSRF token from its cookie)."""

    def api_for(user):
        context = login(user).context
        token = next(c["value"] for c in context.cookies() if c["name"] == "csrftoken")
        return context.request, {"X-CSRFToken": token, "Referer": f"{live_url}/"}

    with registered_world(fleet_admin, keys=("husky",)) as world:
        free_of_slots()
        api, headers = api_for(operator)
        ids = []
        for text in FAR:
            answer = api.post(f"{live_url}/api/instructions", data={"text": text}, headers=headers)
            assert answer.ok, answer.text()
            ids.append(answer.json()["id"])
        first, second = ids

        def queue():
            return api.get(f"{live_url}/api/robots/husky/queue").json()

        shown = wait_for(
            lambda: (q := queue())["running"] and q["running"]["distance_left"] and q, 30, "progress"
        )
        assert shown["running"]["instruction"] == first and shown["running"]["step"] == 1
        assert shown["running"]["eta_s"] > 0 and shown["running"]["distance_left"] > 1
        assert [entry["instruction"] for entry in shown["queued"]] == [second]
        assert wait_for(lambda: moving(world), 30, "husky drives")

        look, look_headers = api_for(viewer)
        assert look.get(f"{live_url}/api/robots/husky/queue").ok
        refused = [
            look.post(f"{live_url}/api/instructions/{first}/cancel", headers=look_headers),
            look.post(
                f"{live_url}/api/robots/husky/queue/{second}/move",
                data={"direction": "up"},
                headers=look_headers,
            ),
            look.post(f"{live_url}/api/robots/husky/lease", headers=look_headers),
            look.post(f"{live_url}/api/stop", data={"robots": ["husky"]}, headers=look_headers),
        ]
        assert [answer.status for answer in refused] == [403] * 4
        assert moving(world), "a viewer's calls changed nothing"

        for pk in (second, first):
            answer = api.post(f"{live_url}/api/instructions/{pk}/cancel", headers=headers)
            assert answer.ok and answer.json()["status"] == "cancelled", answer.text()
        wait_for(lambda: at_rest(world), 15, "husky at rest")
        assert queue()["running"] is None and queue()["queued"] == []

        exported = api.get(f"{live_url}/history/?robot=husky&format=json").json()
        by_id = {row["id"]: row for row in exported}
        assert by_id[first]["status"] == by_id[second]["status"] == "cancelled"
