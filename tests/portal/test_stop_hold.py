"""A robot a person's stop holds: the pages and the API say so ("held by a stop (ada, 10:43:44)") and how to
release it; the Release button (robot page, dashboard row) and the API release it, for operators only."""

import json

import pytest
from django.urls import reverse
from django.utils import timezone

from access import holds
from robots.models import Robot


def held(robot, user) -> str:
    holds.hold([robot], user)
    robot = Robot.objects.select_related("held_by").get(pk=robot.pk)
    assert (
        robot.hold_words == f"held by a stop ({user.username}, {timezone.localtime(robot.held_at):%H:%M:%S})"
    )
    return robot.hold_words


def test_the_pages_show_the_hold_and_a_release_button(client_for, fleet_admin, fleet):
    robot = fleet["turtlebot"]
    words = held(robot, fleet_admin)
    client = client_for(fleet_admin)
    page = client.get(reverse("robot-detail", args=[robot.pk])).content.decode()
    assert words in page and 'id="release-hold"' in page and "release turtlebot" in page
    dashboard = client.get(reverse("dashboard")).content.decode()
    assert words in dashboard and reverse("robot-release-hold", args=[robot.pk]) in dashboard
    holds.release([robot], fleet_admin)
    page = client.get(reverse("robot-detail", args=[robot.pk])).content.decode()
    assert "held by a stop" not in page


def test_the_release_button_releases_for_an_operator_not_a_viewer(
    client, operator, viewer, fleet_admin, fleet
):
    robot = fleet["turtlebot"]
    words = held(robot, fleet_admin)
    url = reverse("robot-release-hold", args=[robot.pk])
    post = {"data": "{}", "content_type": "application/json", "HTTP_ACCEPT": "application/json"}
    client.force_login(viewer)
    assert client.post(url, **post).status_code == 403
    client.force_login(operator)
    reply = client.post(url, **post)
    assert reply.status_code == 200 and reply.json()["detail"] == f"Released turtlebot ({words})."
    assert Robot.objects.get(pk=robot.pk).held_at is None


def test_the_api_shows_the_hold_and_how_to_release_it_and_releases_it(
    client_for, fleet_admin, operator, fleet
):
    robot = fleet["turtlebot"]
    words = held(robot, fleet_admin)
    client = client_for(operator)
    rows = {row["name"]: row for row in client.get("/api/robots").json()}
    assert rows["turtlebot"]["stop_hold"] == words and rows["husky"]["stop_hold"] is None
    assert rows["turtlebot"]["release"].startswith("POST /api/robots/turtlebot/release, or type")
    assert client.get("/api/robots/turtlebot").json()["stop_hold"] == words
    reply = client.post("/api/robots/turtlebot/release", json.dumps({}), content_type="application/json")
    assert reply.status_code == 200 and reply.json()["stop_hold"] is None and reply.json()["release"] is None


def test_history_shows_make_way_as_the_systems_with_its_cause(client_for, viewer, fleet):
    from execution.models import Instruction

    cause = "make way for husky, instruction #14 by ada"
    Instruction.objects.create(text="turtlebot make way for husky", source="traffic", cause=cause)
    page = client_for(viewer).get(reverse("history")).content.decode()
    row = page[page.index("turtlebot make way for husky") :]
    assert f'<td>system<br><span class="muted">{cause}</span></td>' in row[: row.index("</tr>")]


@pytest.mark.browser
@pytest.mark.timeout(90)
def test_a_stop_shows_its_hold_live_in_the_row_and_release_lets_it_go(login, operator, fleet, live_url):
    page = login(operator)
    page.goto(f"{live_url}/robots/")
    page.wait_for_selector("#conn[data-state=live]")
    page.get_by_label("Select turtlebot").check()
    page.get_by_role("button", name="Stop selected").click()
    row = "#robot-table tr[data-name=turtlebot]"
    page.wait_for_selector(f"{row} .stop-hold:has-text('held by a stop (otto, ')")
    page.get_by_role("button", name="Release turtlebot from its stop").click()
    page.wait_for_selector(".toast:not(.bad):has-text('Released turtlebot (held by a stop (otto, ')")
    page.wait_for_selector(f"{row} .stop-hold", state="detached")
