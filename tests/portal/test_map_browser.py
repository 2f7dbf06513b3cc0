"""The live map in a real browser: zoom about the cursor, pan, every robot of a crowd named, pages that fit."""

import json
import math

import pytest

from robots.models import Robot

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

CROWD = [f"crowd{i}" for i in range(8)]


def _live(page):
    page.wait_for_selector("#conn[data-state=live]")
    page.wait_for_function("() => window.fleet && window.fleet.map && window.fleet.map.robots.size > 0")


def _canvas_point(page, fx: float, fy: float) -> tuple[float, float]:
    box = page.locator("#fleet-map").bounding_box()
    return box["x"] + box["width"] * fx, box["y"] + box["height"] * fy


def test_the_wheel_zooms_about_the_cursor_and_a_drag_pans(login, operator, fleet):
    page = login(operator)
    _live(page)
    x, y = _canvas_point(page, 0.3, 0.6)
    page.mouse.move(x, y)
    before = page.evaluate(
        "([x, y]) => ({ at: window.fleet.map.worldAt(x, y), scale: window.fleet.map.scale })", [x, y]
    )
    page.mouse.wheel(0, -500)
    page.wait_for_function("(s) => window.fleet.map.scale > 1.5 * s", arg=before["scale"])
    after = page.evaluate(
        "([x, y]) => ({ at: window.fleet.map.worldAt(x, y), scale: window.fleet.map.scale })", [x, y]
    )
    assert after["scale"] > 1.5 * before["scale"]
    assert math.dist(before["at"], after["at"]) < 0.002  # the point under the cursor stayed under it (metres)

    page.mouse.down()
    page.mouse.move(x + 80, y + 40, steps=5)
    page.mouse.up()
    panned = page.evaluate("([x, y]) => window.fleet.map.worldAt(x, y)", [x + 80, y + 40])
    assert math.dist(panned, before["at"]) < 0.005  # the map moved with the pointer
    page.get_by_role("button", name="Fit the whole map and every robot").click()
    page.wait_for_function("() => Math.abs(window.fleet.map.zoom - 1) < 0.05")


def test_every_robot_of_a_crowd_is_named_on_the_map_and_in_its_card(login, operator, fleet):
    for i, name in enumerate(CROWD):  # eight robots within 7 cm of each other
        Robot.objects.create(
            name=name, model="turtlebot3_burger", endpoint="ws://127.0.0.1:9", namespace=f"/{name}",
            state=Robot.State.READY,
            start_pose=[0.5 + 0.01 * (i % 4), 0.5 + 0.02 * (i // 4), 0.0],
        )  # fmt: skip
    page = login(operator)
    _live(page)
    page.wait_for_function("(n) => window.fleet.map.labelled.length >= n", arg=len(CROWD))
    labels = page.evaluate("() => window.fleet.map.labels.map((l) => ({ name: l.name, box: l.box }))")
    assert set(CROWD) <= {label["name"] for label in labels}
    for i, a in enumerate(labels):  # no label covers another
        for b in labels[i + 1 :]:
            (ax, ay, aw, ah), (bx, by, bw, bh) = a["box"], b["box"]
            assert not (ax < bx + bw and bx < ax + aw and ay < by + bh and by < ay + ah), (a, b)

    # hovering the crowd opens a card that names every robot there
    centre = page.evaluate(
        "() => { const m = window.fleet.map, r = window.devicePixelRatio || 1, box = m.canvas.getBoundingClientRect();"
        " const [x, y] = m.toScreen(0.515, 0.51); return [box.left + x / r, box.top + y / r]; }"
    )
    page.mouse.move(*centre)
    card = page.locator(".map-card")
    card.wait_for(state="visible")
    text = card.inner_text()
    for name in CROWD:
        assert name in text


@pytest.mark.parametrize("width,height", [(1280, 800), (1024, 768)])
def test_dashboard_and_robot_page_fit_the_window(login, operator, fleet, live_url, width, height):
    robot = fleet["turtlebot"]  # long names, as TIAGo's graph has them
    for i in range(12):
        robot.topics.create(
            name=f"/move_base/NavfnROS/make_plan_{i}", type="move_base_msgs/MoveBaseActionFeedback"
        )
        robot.services.create(name=f"/move_base/clear_costmaps_{i}", type="nav_msgs/GetPlan")
        robot.nodes.create(name=f"/xtion/rgb/image_raw_compressed_{i}")
    robot.description = {
        "wheel_joints": [f"wheel_joint_number_{i}" for i in range(8)],
        "limits_source": "x" * 80,
    }
    robot.save()
    page = login(operator, width=width, height=height)
    _live(page)
    overflow = "() => document.documentElement.scrollWidth - window.innerWidth"
    assert page.evaluate(overflow) <= 0
    page.goto(f"{live_url}/robots/{fleet['turtlebot'].pk}/")
    _live(page)
    assert page.evaluate(overflow) <= 0
    assert page.locator("#fleet-map").bounding_box()["width"] > 300  # the same map, on the robot page


def test_the_map_grows_with_the_window(login, operator, fleet):
    page = login(operator, width=1280, height=800)
    _live(page)
    small = page.locator("#fleet-map").bounding_box()
    page.set_viewport_size({"width": 1920, "height": 1080})
    page.wait_for_function(
        "(w) => document.querySelector('#fleet-map').getBoundingClientRect().width > w",
        arg=1.3 * small["width"],
    )
    large = page.locator("#fleet-map").bounding_box()
    assert large["width"] > 1.3 * small["width"] and large["height"] > 1.2 * small["height"]


def test_a_goal_dragged_in_goal_mode_sends_the_selected_robots_with_a_heading(login, operator, fleet):
    sent = []

    def answer(route):
        sent.append(json.loads(route.request.post_data))
        instruction = {"id": 1, "text": "move", "status": "queued", "type": "I", "parse": {}, "outcome": ""}
        route.fulfill(status=201, content_type="application/json", body=json.dumps(instruction))

    page = login(operator)
    page.route("**/api/instructions", answer)
    _live(page)
    page.get_by_label("Select turtlebot").check()
    page.get_by_role("button", name="Goal mode").click()
    x, y = _canvas_point(page, 0.5, 0.5)
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x - 50, y, steps=5)  # to the left of the screen: heading west (pi)
    page.mouse.up()
    page.wait_for_function("() => document.querySelector('#progress li') !== null")
    [body] = sent
    assert body["robot_ids"] == [fleet["turtlebot"].pk]
    destination = body["destination"]
    assert math.dist((destination["x"], destination["y"]), (0.5, 0.5)) < 0.05  # the middle of the 1 m map
    assert abs(abs(destination["yaw"]) - math.pi) < 0.01


def test_two_fingers_pinch_to_zoom(login, operator, fleet):
    page = login(operator)
    _live(page)
    x, y = _canvas_point(page, 0.5, 0.5)
    before = page.evaluate("() => window.fleet.map.scale")
    cdp = page.context.new_cdp_session(page)
    cdp.send("Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 2})

    def touch(kind, spread):
        points = [{"x": x - spread, "y": y, "id": 1}, {"x": x + spread, "y": y, "id": 2}]
        cdp.send(
            "Input.dispatchTouchEvent", {"type": kind, "touchPoints": [] if kind == "touchEnd" else points}
        )

    touch("touchStart", 30)
    for spread in range(40, 130, 10):
        touch("touchMove", spread)
    touch("touchEnd", 0)
    page.wait_for_function("(s) => window.fleet.map.scale > 2.5 * s", arg=before)


NEAREST = """(rows) => {
  const map = window.fleet.map, m = map.map;
  const [cx, cy] = [m.origin[0] + m.width * m.resolution / 2, m.origin[1] + m.height * m.resolution / 2];
  const step = 70 * map.ratio / map.scale; // robots 70 css px apart: a label is about as wide
  const robots = [];
  rows.forEach((row, j) => row.forEach((state, i) => robots.push(
    { id: 2000 + robots.length, name: `r${j}${i}`, state, start_pose: [cx + (i - 2) * step, cy - j * step, 0] })));
  map.setRobots(robots);
  map.draw();
  const centre = (name) => { const r = [...map.robots.values()].find((x) => x.name === name); return map.toScreen(...map.where(r)); };
  const distance = ([x, y, w, h], [px, py]) => Math.hypot(Math.max(x - px, 0, px - x - w), Math.max(y - py, 0, py - y - h));
  return map.labels.map((label) => {
    const nearest = robots.map((r) => [distance(label.box, centre(r.name)), r.name]).sort((a, b) => a[0] - b[0])[0][1];
    return [label.name, nearest];
  });
}"""


def test_in_a_crowd_each_label_sits_nearer_its_own_robot_than_any_other(login, operator, fleet):
    page = login(operator)
    _live(page)
    rows = [
        ["ready", "motion", "ready", "registered", "ready"],
        ["ready", "ready", "motion", "ready", "ready"],
    ]
    placed = page.evaluate(NEAREST, rows)
    assert len(placed) == 10  # every robot named
    assert [name for name, nearest in placed if name != nearest] == []  # each label reads as its own robot's
