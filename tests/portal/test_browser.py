"""The portal in a real browser (Playwright driving Debian's chromium against a live ASGI server)."""

import threading

import pytest

from access import leases

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90)]


def _live(page):
    """Wait until the page's WebSocket delivered its snapshot."""
    page.wait_for_selector("#conn[data-state=live]")


def test_viewer_has_no_control(login, viewer, fleet, live_url):
    page = login(viewer)
    _live(page)
    assert page.locator("#stop-all").count() == 0
    assert page.get_by_label("Instruction", exact=True).count() == 0
    # state shown by a glyph and a word, not by colour alone
    page.wait_for_selector(
        "#robot-table tr[data-name=turtlebot] .state[data-state=ready]:has-text('● ready')"
    )
    page.goto(f"{live_url}/robots/{fleet['turtlebot'].pk}/")
    _live(page)
    assert page.get_by_role("button", name="Take control").count() == 0
    assert page.get_by_role("group", name="Teleoperation").count() == 0
    # and the server refuses the viewer's stop even when sent by hand over the page's own socket
    page.evaluate(
        "() => { window.__replies = []; const s = new WebSocket(`ws://${location.host}/ws/fleet/`);"
        " s.onmessage = (e) => window.__replies.push(JSON.parse(e.data));"
        " s.onopen = () => s.send(JSON.stringify({command: 'stop', robots: 'all'})); }"
    )
    page.wait_for_function("() => window.__replies.some((m) => m.type === 'command.result')")
    reply = page.evaluate("() => window.__replies.find((m) => m.type === 'command.result')")
    assert reply["ok"] is False and "may not stop" in reply["detail"]


def test_second_operator_cannot_command_a_robot_held_by_the_first(
    login, operator, second_operator, fleet, live_url
):
    robot = fleet["turtlebot"]
    first = login(operator)
    first.goto(f"{live_url}/robots/{robot.pk}/")
    _live(first)
    first.get_by_role("button", name="Take control").click()
    first.wait_for_selector("#holder[data-holder=otto]")

    second = login(second_operator)
    second.goto(f"{live_url}/robots/{robot.pk}/")
    _live(second)
    assert second.locator("#holder").inner_text().startswith("held by otto until ")
    second.get_by_role("button", name="Take control").click()
    second.wait_for_selector(".toast.bad:has-text('held by otto')")
    # the pad is off and says why, once (tests/portal/test_telemetry_browser.py: no flood of refusals)
    assert second.get_by_role("button", name="Forward").is_disabled()
    second.wait_for_selector("#teleop-note:has-text('Held by otto until')")
    assert leases.holder(robot) == operator


def test_operator_sees_the_lease_taken_elsewhere_live(login, operator, second_operator, fleet, live_url):
    robot = fleet["turtlebot"]
    watcher = login(second_operator)
    _live(watcher)
    page = login(operator)
    page.goto(f"{live_url}/robots/{robot.pk}/")
    _live(page)
    page.get_by_role("button", name="Take control").click()
    watcher.wait_for_selector("#robot-table tr[data-name=turtlebot] .held:has-text('held by otto')")


def test_robot_list_takes_stops_and_releases_the_selected_robots(
    login, operator, second_operator, fleet, live_url
):
    turtlebot, husky = fleet["turtlebot"], fleet["husky"]
    taking = threading.Thread(target=leases.take, args=(second_operator, husky))  # off Playwright's loop
    taking.start()
    taking.join()
    page = login(operator)
    page.goto(f"{live_url}/robots/")
    _live(page)
    page.get_by_role("button", name="Take control").click()
    page.wait_for_selector(".toast.bad:has-text('Select one or more robots')")  # nothing selected yet

    page.get_by_label("Select turtlebot").check()
    page.get_by_label("Select husky").check()
    page.get_by_role("button", name="Take control").click()
    page.wait_for_selector("#robot-table tr[data-name=turtlebot] .held:has-text('held by otto')")
    page.wait_for_selector(".toast.bad:has-text('husky')")  # olga holds it: refused in words, not taken
    assert leases.holder(turtlebot) == operator and leases.holder(husky) == second_operator

    page.get_by_role("button", name="Stop selected").click()
    page.wait_for_selector(".toast:not(.bad):has-text('Stopped'):has-text('turtlebot')")

    page.get_by_role("button", name="Release control").click()
    page.wait_for_selector("#robot-table tr[data-name=turtlebot] .held:has-text('free')")
    assert leases.holder(turtlebot) is None and leases.holder(husky) == second_operator


def test_filter_and_select_all_shown_act_on_the_robots_in_view_only(login, operator, fleet, live_url):
    page = login(operator)
    page.goto(f"{live_url}/robots/")
    _live(page)
    page.wait_for_selector("#robot-count:has-text('2 robots')")
    page.get_by_label("Filter").fill("HUS")  # any case; name, model, state or holder
    page.wait_for_selector("#robot-count:has-text('1 of 2 shown')")
    assert page.locator("#robot-table tr[data-name=turtlebot]").is_hidden()
    page.get_by_label("Select all robots shown").check()
    page.get_by_role("button", name="Take control").click()
    page.wait_for_selector("#robot-table tr[data-name=husky] .held:has-text('held by otto')")
    assert leases.holder(fleet["turtlebot"]) is None  # the hidden robot was not acted on

    page.get_by_label("Filter").fill("")
    page.wait_for_selector("#robot-count:has-text('2 robots')")
    assert page.locator("#robot-table tr[data-name=turtlebot]").is_visible()
    assert not page.get_by_label("Select turtlebot").is_checked()
    pick_all = page.get_by_label("Select all robots shown")  # half-ticked: one of the two shown is
    assert not pick_all.is_checked() and pick_all.evaluate("(box) => box.indeterminate")
    page.get_by_label("Select turtlebot").check()
    assert pick_all.is_checked() and not pick_all.evaluate("(box) => box.indeterminate")


LABELS = """(spots) => {
  const map = window.fleet.map, m = map.map;
  const [cx, cy] = [m.origin[0] + m.width * m.resolution / 2, m.origin[1] + m.height * m.resolution / 2];
  map.setRobots(spots.map(([name, state, dx], id) => ({ id: 1000 + id, name, state, start_pose: [cx + dx, cy, 0] })));
  map.draw();
  return map.labelled;
}"""


def test_map_labels_that_would_cover_each_other_move_aside_busy_robots_first(login, operator, fleet):
    page = login(operator)
    _live(page)
    crowded = [("idle1", "ready", 0.0), ("mover", "motion", 0.01), ("idle2", "registered", 0.02)]
    # one place, three labels: the robot under way keeps its place above, the others move out on leader lines
    assert page.evaluate(LABELS, crowded) == ["mover", "idle1", "idle2"]
    # on the 1 m map (off-screen robots get no label)
    apart = [("left", "ready", -0.3), ("right", "ready", 0.3)]
    assert sorted(page.evaluate(LABELS, apart)) == ["left", "right"]


def test_usable_on_a_768px_tablet(login, operator, fleet):
    page = login(operator, width=768, height=1024)
    _live(page)
    assert page.locator("#stop-all").is_visible()
    assert page.get_by_label("Instruction", exact=True).is_visible()
    overflow = page.evaluate("() => document.documentElement.scrollWidth - window.innerWidth")
    assert overflow <= 0
