"""Telemetry, teleop and sensors in a real browser against the simulated paper world.

A synthetic gamepad (navigator.getGamepads replaced before the page loads) drives a simulated TurtleBot: the
simulator's own pose says it moved. Battery, round trip and speed change live on the robot page and in the
dashboard's table; TIAGo's page shows its (synthetic) camera and its laser scan on the map.
"""

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import pytest

from access import leases
from robots.models import Robot
from tests.portal.demo import demo_world, pose_stream

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(180)]

# A gamepad the page reads through the Gamepad API; the test moves its stick and buttons via window.__pad.
FAKE_GAMEPAD = """
window.__pad = { id: "synthetic pad (standard)", index: 0, connected: true, mapping: "standard", timestamp: 0,
  axes: [0, 0, 0, 0], buttons: Array.from({ length: 17 }, () => ({ pressed: false, touched: false, value: 0 })) };
navigator.getGamepads = () => [window.__pad, null, null, null];
"""
PRESS = (
    "([button, forward]) => { window.__pad.buttons[button].pressed = true; window.__pad.axes[1] = -forward; }"
)
RELEASE = "() => { window.__pad.buttons.forEach((b) => { b.pressed = false; }); window.__pad.axes[1] = 0; }"


@contextmanager
def registered_world(user, keys=("turtlebot", "tiago")):
    """The paper world running with these endpoints registered and their poses streamed to the pages."""
    from robots.registration import register_endpoints

    with demo_world() as world:
        with ThreadPoolExecutor(1) as pool:  # registration runs its own event loop; Playwright holds this one
            pool.submit(register_endpoints, [world.urls[key] for key in keys], user).result(timeout=60)
        with pose_stream():
            yield world


def _wait(condition, what: str, seconds: float = 30.0):
    deadline = time.monotonic() + seconds
    while not (value := condition()):
        assert time.monotonic() < deadline, f"not within {seconds:g} s: {what}"
        time.sleep(0.1)
    return value


def test_a_synthetic_gamepad_drives_the_robot_and_telemetry_changes_live(
    login, operator, live_url, fleet_admin
):
    with registered_world(fleet_admin) as world:
        robot = Robot.objects.get(name="turtlebot")
        page = login(operator)
        page.add_init_script(FAKE_GAMEPAD)
        page.goto(f"{live_url}/robots/{robot.pk}/")
        page.wait_for_selector("#conn[data-state=live]")
        page.wait_for_selector("#gamepad-status:has-text('hold LB')")
        page.get_by_role("button", name="Take control").click()
        page.wait_for_selector("#holder[data-holder=otto]")
        page.wait_for_function("() => /%/.test(document.querySelector('#t-battery').textContent)")
        page.wait_for_function("() => /ms/.test(document.querySelector('#t-rtt').textContent)")
        battery_before = page.evaluate("() => window.fleet.robot.pose.battery")
        start = world.pose("turtlebot")

        page.evaluate(PRESS, [4, 0.8])  # dead-man held, stick forward
        page.wait_for_selector("#robot-state[data-state=teleop]")
        page.wait_for_function("() => parseFloat(document.querySelector('#t-speed').textContent) > 0.05")
        _wait(
            lambda: math.dist(world.pose("turtlebot")[:2], start[:2]) > 0.3, "the simulated robot drove 0.3 m"
        )
        page.wait_for_function(
            "(b) => window.fleet.robot.pose.battery < b", arg=battery_before
        )  # drains faster
        page.wait_for_function("() => window.fleet.plots.series.t.length > 5")  # the live plots have points

        page.evaluate(RELEASE)  # dead-man let go: the robot stops
        page.wait_for_function("() => parseFloat(document.querySelector('#t-speed').textContent) < 0.01")
        stopped = world.pose("turtlebot")
        time.sleep(0.5)
        assert math.dist(world.pose("turtlebot")[:2], stopped[:2]) < 0.02

        # the stick alone (dead-man not held) drives nothing
        page.evaluate("() => { window.__pad.axes[1] = -1; }")
        time.sleep(0.6)
        assert math.dist(world.pose("turtlebot")[:2], stopped[:2]) < 0.02

        # the touch joystick: pushed up, the robot drives; let go, it stops
        page.evaluate("() => { window.__pad.axes[1] = 0; }")
        box = page.locator("#joystick").bounding_box()
        centre = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.move(*centre)
        page.mouse.down()
        page.mouse.move(centre[0], centre[1] - box["height"] * 0.4, steps=4)
        _wait(lambda: math.dist(world.pose("turtlebot")[:2], stopped[:2]) > 0.15, "the joystick drove 0.15 m")
        page.mouse.up()
        page.wait_for_function("() => parseFloat(document.querySelector('#t-speed').textContent) < 0.01")

        # and the dashboard's table shows the same telemetry
        page.goto(f"{live_url}/")
        page.wait_for_selector("#conn[data-state=live]")
        row = f"#robot-table tr[data-robot-id='{robot.pk}']"
        page.wait_for_selector(f"{row} .t-battery:has-text('%')")
        page.wait_for_selector(f"{row} .t-rtt:has-text('ms')")
        page.wait_for_selector(f"{row} .t-seen:has-text('ago')")


def test_tiago_page_shows_its_camera_and_its_laser_scan_on_the_map(login, operator, live_url, fleet_admin):
    with registered_world(fleet_admin, keys=("tiago",)):
        robot = Robot.objects.get(name="tiago")
        page = login(operator)
        page.goto(f"{live_url}/robots/{robot.pk}/")
        page.wait_for_selector("#conn[data-state=live]")
        page.wait_for_function("() => Number(document.querySelector('#camera').dataset.frames || 0) >= 2")
        size = page.evaluate(
            "() => { const i = document.querySelector('#camera'); return [i.naturalWidth, i.naturalHeight]; }"
        )
        assert size == [160, 120]
        page.wait_for_function("() => window.fleet.map.scan && window.fleet.map.scan.points.length > 50")


def test_a_robot_held_by_someone_else_disables_the_pad_with_one_message(
    login, operator, second_operator, fleet, live_url
):
    robot = fleet["turtlebot"]
    taking = threading.Thread(target=leases.take, args=(second_operator, robot))  # off Playwright's loop
    taking.start()
    taking.join()
    page = login(operator)
    page.add_init_script(FAKE_GAMEPAD)
    page.goto(f"{live_url}/robots/{robot.pk}/")
    page.wait_for_selector("#conn[data-state=live]")
    note = page.locator("#teleop-note")
    note.wait_for(state="visible")
    assert note.inner_text().startswith("Held by olga until ")
    assert page.get_by_role("button", name="Forward").is_disabled()
    page.evaluate(PRESS, [4, 1.0])  # a gamepad held down for a second: still no flood of refusals
    page.keyboard.press("ArrowUp")
    time.sleep(1.0)
    assert page.locator(".toast.bad").count() == 0
    assert note.inner_text().startswith("Held by olga until ")


def test_a_goal_dragged_on_the_map_sends_the_robot_there_facing_the_drag(
    seeded_terms, login, operator, live_url, fleet_admin, eager_celery, executor
):
    with registered_world(fleet_admin, keys=("turtlebot",)) as world:
        x0, y0, _ = world.pose("turtlebot")
        goal = (round(x0 + 0.6, 2), round(y0, 2))
        page = login(operator)
        page.wait_for_selector("#conn[data-state=live]")
        page.get_by_label("Select turtlebot").check()
        page.get_by_role("button", name="Goal mode").click()
        start = page.evaluate(
            "([x, y]) => { const m = window.fleet.map, r = window.devicePixelRatio || 1;"
            " m.layout(); const box = m.canvas.getBoundingClientRect(); const [px, py] = m.toScreen(x, y);"
            " return [box.left + px / r, box.top + py / r]; }",
            list(goal),
        )
        page.mouse.move(*start)
        page.mouse.down()
        page.mouse.move(start[0], start[1] - 60, steps=6)  # up the screen: north, +y on the map
        page.mouse.up()
        page.wait_for_selector(".parse")
        from execution.models import Instruction

        assert (
            "facing 90°" in _wait(lambda: Instruction.objects.order_by("-pk").first(), "an instruction").text
        )

        def arrived():
            x, y, yaw = world.pose("turtlebot")
            return (
                math.dist((x, y), goal) < 0.2 and abs(math.remainder(yaw - math.pi / 2, 2 * math.pi)) < 0.15
            )

        _wait(arrived, f"turtlebot at {goal} facing north", seconds=60)
