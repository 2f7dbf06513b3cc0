"""Alerts in a real browser: raised live on any page (badge and toast), handled on /alerts/ by an operator."""

import threading

import pytest

import alerts

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90)]


def raise_elsewhere(*args) -> None:
    """Raise an alert from another thread, as a worker would (Playwright's loop owns this one)."""
    thread = threading.Thread(target=alerts.raise_alert, args=args)
    thread.start()
    thread.join(10)


def test_a_raised_alert_shows_on_the_dashboard_and_an_operator_resolves_it(login, operator, fleet, live_url):
    page = login(operator)
    page.wait_for_selector("#conn[data-state=live]")
    page.wait_for_selector("#alerts-badge[data-count='0']")
    raise_elsewhere("robot_stuck", fleet["turtlebot"], "turtlebot: blocked by husky at A")
    page.wait_for_selector("#alerts-badge[data-count='1']")
    page.wait_for_selector(".toast:has-text('robot stuck: turtlebot: blocked by husky at A')")

    page.click("#alerts-link")
    row = page.locator("#alerts-open tr[data-alert]")
    assert "blocked by husky at A" in row.inner_text()
    row.get_by_role("button", name="Acknowledge").click()
    page.wait_for_selector("#alerts-open tr[data-alert]:has-text('acknowledged by otto')")
    page.locator("#alerts-open tr[data-alert]").get_by_role("button", name="Resolve").click()
    page.wait_for_selector("#alerts-badge[data-count='0']")
    assert page.locator("#alerts-open tr[data-alert]").count() == 0
    page.reload()
    assert "blocked by husky at A" in page.locator("#alerts-resolved").inner_text()


def test_a_viewer_sees_the_badge_but_no_buttons(login, viewer, fleet, live_url):
    raise_elsewhere("robot_offline", fleet["husky"], "link to ws://127.0.0.1:9092 lost")
    page = login(viewer)
    page.wait_for_selector("#alerts-badge[data-count='1']")
    page.goto(f"{live_url}/alerts/")
    assert "link to ws://127.0.0.1:9092 lost" in page.locator("#alerts-open").inner_text()
    assert page.locator("#alerts-open button").count() == 0
