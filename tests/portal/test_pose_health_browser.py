"""The dashboard with one robot publishing NaN odometry and with a frozen pose stream, in a real browser: the
other robots keep moving on the map, the bad one says why, a frame the page cannot read costs only itself, and
the whole fleet is marked stale when poses stop coming."""

from concurrent.futures import ThreadPoolExecutor

import pytest

from places.worlds import load_world_into_db
from robots.registration import register_endpoints
from simworker.testing import bad_odometry, running_world
from tests.portal.demo import pose_stream

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(150)]

ROBOT = "[...window.fleet.map.robots.values()].find((r) => r.name === name)"
POSE_T = f"(name) => {{ const r = {ROBOT}; return r && r.pose ? r.pose.t || 0 : 0; }}"
LABEL = "(name) => (window.fleet.map.labelTexts || []).find((text) => text.includes(` ${name}`)) || ''"


def _newer(page, name: str, than: float) -> None:
    page.wait_for_function(f"([name, t]) => ({POSE_T})(name) > t", arg=[name, than], timeout=20000)


def test_one_robot_with_nan_odometry_freezes_nothing_and_a_frozen_stream_marks_the_fleet_stale(
    login, operator, live_url
):
    with running_world("paper", endpoints=["robots"]) as sim:
        with ThreadPoolExecutor(1) as thread:  # registration runs its own event loop; Playwright's is here
            results = thread.submit(register_endpoints, [sim.urls["robots"]]).result(timeout=60)
        assert all(result.ok for result in results)
        load_world_into_db("paper")
        with pose_stream():
            page = login(operator)
            said = []
            page.on("console", lambda message: said.append(message.text))
            sockets = []
            page.route_web_socket("**/ws/fleet/", lambda ws: sockets.append(ws) or ws.connect_to_server())
            page.reload()
            page.wait_for_selector("#conn[data-state=live]")
            _newer(page, "robot1", 0)
            _newer(page, "robot2", 0)
            assert page.locator("#fleet-stale").is_hidden()

            sim.call(bad_odometry, sim.fleet, "robot2", "nan")
            page.wait_for_function(f"() => ({LABEL})('robot2').includes('odometry invalid: x is NaN')")
            row = page.locator("tr:has-text('robot2') .t-trouble")
            assert row.inner_text() == "odometry invalid: x is NaN"
            _newer(page, "robot1", page.evaluate(POSE_T, "robot1"))  # the ticks carrying robot2 still read

            # frames a browser cannot use (not JSON; a bare NaN, as the portal once sent) cost only themselves
            sockets[0].send("{not json")
            sockets[0].send('{"type": "fleet.poses", "poses": [{"id": 1, "x": NaN, "y": 0, "t": 1}]}')
            sockets[0].send('{"type": "fleet.poses", "poses": 7}')
            _newer(page, "robot1", page.evaluate(POSE_T, "robot1"))  # robot1 still moves on the map
            assert sum("unreadable message dropped" in text for text in said) == 2, said
            assert "odometry invalid" not in page.evaluate(LABEL, "robot1")

        # the pose stream is gone (a links process frozen): nothing comes that could say so; the page tells
        page.wait_for_selector("#fleet-stale:not([hidden])", timeout=15000)
        assert "Fleet stale" in page.locator("#fleet-stale").inner_text()
        page.wait_for_function(f"() => ({LABEL})('robot1').includes('stale (')")
        assert page.locator("tr:has-text('robot1') .t-trouble").inner_text().startswith("stale (")
