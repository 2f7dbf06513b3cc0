"""A phone (390 x 844): every page fits its width without sideways scrolling, and on a robot's page the teleop
pad and on the dashboard the STOP button are reachable without scrolling past the map."""

import pytest

from tests.portal.pages import every_page

pytestmark = [pytest.mark.browser, pytest.mark.timeout(180)]

PHONE = {"width": 390, "height": 844}

# what overflows, for the failure message: the widest elements reaching past the window's right edge
WIDEST = """() => [...document.querySelectorAll("body *")]
  .map((e) => [e, e.getBoundingClientRect()])
  .filter(([e, r]) => r.right > window.innerWidth + 0.5 && getComputedStyle(e).position !== "fixed")
  .filter(([e]) => !e.closest(".scroll, .table-scroll, pre"))
  .slice(0, 6).map(([e, r]) => `${e.tagName.toLowerCase()}#${e.id}.${[...e.classList].join(".")} ${Math.round(r.right)}`)"""


def test_every_page_fits_a_phone(login, operator, fleet_admin, fleet, live_url, tmp_path):
    pages = every_page(fleet["turtlebot"], tmp_path)
    widths = {}
    for user in (operator, fleet_admin):
        page = login(user, **PHONE)
        for name, path in pages.items():
            if name in {"audit", "admin"} and user is operator:
                continue
            page.goto(f"{live_url}{path}")
            page.wait_for_load_state("load")
            page.wait_for_timeout(300)  # the page's scripts have drawn
            width = page.evaluate("document.scrollingElement.scrollWidth")
            widths[(user.username, name)] = (width, page.evaluate(WIDEST) if width > 390 else [])
    too_wide = {key: value for key, value in widths.items() if value[0] > 390}
    assert not too_wide, too_wide


def test_on_a_phone_stop_and_the_teleop_pad_are_on_the_first_screen(login, operator, fleet, live_url):
    """Without scrolling: STOP ALL on the dashboard, the pad on a robot's page (its map comes after control)."""
    page = login(operator, **PHONE)
    stop = page.locator("#stop-all").bounding_box()
    assert stop["y"] >= 0 and stop["y"] + stop["height"] <= PHONE["height"]
    page.goto(f"{live_url}/robots/{fleet['turtlebot'].pk}/")
    pad, map_box = page.locator("#teleop").bounding_box(), page.locator("#fleet-map").bounding_box()
    assert pad["y"] + pad["height"] <= PHONE["height"], pad
    assert pad["y"] < map_box["y"]
    page.mouse.wheel(0, 600)  # scrolled down, STOP ALL is still at hand (the top bar stays)
    page.wait_for_timeout(200)
    stop = page.locator("#stop-all").bounding_box()
    assert stop["y"] >= 0 and stop["y"] + stop["height"] <= PHONE["height"]


def test_stop_all_is_in_one_place_on_every_page(login, operator, fleet, live_url, tmp_path):
    """At 1280 px and on a phone: the same spot whatever the page's top bar holds (a socket's pill or none)."""
    pages = every_page(fleet["turtlebot"], tmp_path)
    for size in ({"width": 1280, "height": 800}, PHONE):
        page = login(operator, **size)
        boxes = {}
        for name in ("dashboard", "robot", "history", "experiments", "recordings", "alerts"):
            page.goto(f"{live_url}{pages[name]}")
            box = page.locator("#stop-all").bounding_box()
            boxes[name] = (round(box["x"]), round(box["y"]))
        assert len(set(boxes.values())) == 1, (size, boxes)
        assert boxes["dashboard"][0] > size["width"] / 2  # top right
