"""The robot page's telemetry in a browser against the simulated paper world: the /diagnostics panel (each
component's level as the simulated robot publishes it, escaped, STALE when it goes quiet), the topic inspector
(type, rate, latest message; a viewer may look, nothing is published; only the robot's topics), the plots' time
axis at sane intervals, and ArrowDown on the teleop pad driving straight back (the simulator's pose says so)."""

import itertools
import math
import time

import pytest

from robots.models import Robot, Topic
from simworker.testing import bad_odometry
from tests.execution.helpers import wait_for
from tests.portal.test_tasklist_browser import at_rest
from tests.portal.test_telemetry_browser import registered_world

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(180)]

ROW = "#diagnostics tr[data-component='{name}'][data-level='{level}']"


def set_charge(world, name: str, charge: float) -> None:
    def run():
        world.fleet.robots[name].charge = charge

    world.call(run)


def test_a_viewer_reads_diagnostics_and_inspects_topics_without_moving_the_robot(
    login, viewer, live_url, fleet_admin
):
    with registered_world(fleet_admin, keys=("husky",)) as world:
        robot = Robot.objects.get(name="husky")
        page = login(viewer)
        page.goto(f"{live_url}/robots/{robot.pk}/")
        page.wait_for_selector("#conn[data-state=live]")
        for component in ("battery", "motors", "odometry"):
            page.wait_for_selector(ROW.format(name=component, level="OK"))

        set_charge(world, "husky", 0.2)  # below 30 %: the battery warns
        page.wait_for_selector(ROW.format(name="battery", level="WARN"))
        assert "20 %" in page.locator(ROW.format(name="battery", level="WARN")).inner_text()
        world.call(
            bad_odometry, world.fleet, "husky", "<img src=x id=injected>"
        )  # a robot's words, not markup
        odometry = page.locator(ROW.format(name="odometry", level="ERROR"))
        odometry.wait_for()
        assert "<img src=x id=injected>" in odometry.inner_text()
        assert page.locator("#injected").count() == 0
        world.call(bad_odometry, world.fleet, "husky", None)

        odom = Topic.objects.get(robot=robot, name="/husky_velocity_controller/odom")
        page.get_by_label("Topic", exact=True).fill(odom.name)
        page.get_by_role("button", name="Inspect").click()
        page.wait_for_function("() => Number(document.querySelector('#inspect-info').dataset.rate) > 5")
        info = page.locator("#inspect-info").inner_text()
        assert "nav_msgs/Odometry" in info and "≥ " in info, info  # 20 Hz, seen through a 10 Hz throttle
        assert '"pose"' in page.locator("#inspect-message").inner_text()

        page.get_by_label("Topic", exact=True).fill("/diagnostics")
        page.get_by_role("button", name="Inspect").click()
        page.wait_for_function(
            "() => { const r = Number(document.querySelector('#inspect-info').dataset.rate);"
            " return r > 0.7 && r < 1.4; }",
            timeout=20000,
        )  # /diagnostics once a second
        assert "diagnostic_msgs/DiagnosticArray" in page.locator("#inspect-info").inner_text()

        page.get_by_label("Topic", exact=True).fill("/husky_velocity_controller/cmd_vel")
        page.get_by_role("button", name="Inspect").click()
        page.wait_for_selector("#inspect-info:has-text('inspecting /husky_velocity_controller/cmd_vel')")
        page.get_by_label("Topic", exact=True).fill("/rosout_not_here")
        page.get_by_role("button", name="Inspect").click()
        page.wait_for_selector("#inspect-info:has-text('not a topic of this robot')")
        assert at_rest(world), "looking at husky's topics moved it"

        set_charge(world, "husky", 0.8)
        page.wait_for_selector(ROW.format(name="battery", level="OK"))


def test_robots_sharing_an_endpoint_each_show_their_own_diagnostics(login, viewer, live_url, fleet_admin):
    with registered_world(fleet_admin, keys=("robots",)):  # robot1..robot4 under namespaces, one /diagnostics
        page = login(viewer)
        for name in ("robot3", "robot1"):
            page.goto(f"{live_url}/robots/{Robot.objects.get(name=name).pk}/")
            page.wait_for_selector(ROW.format(name=f"{name}/battery", level="OK"))
            page.wait_for_selector(ROW.format(name=f"{name}/motors", level="OK"))
            page.wait_for_timeout(2500)  # two more seconds of every robot's arrays
            shown = page.eval_on_selector_all(
                "#diagnostics tr[data-component]", "rows => rows.map((r) => r.dataset.component)"
            )
            assert shown and all(component.startswith(f"{name}/") for component in shown), shown


def test_diagnostics_of_a_quiet_robot_go_stale(login, viewer, live_url, fleet_admin):
    with registered_world(fleet_admin, keys=("husky",)) as world:
        robot = Robot.objects.get(name="husky")
        page = login(viewer)
        page.goto(f"{live_url}/robots/{robot.pk}/")
        page.wait_for_selector(ROW.format(name="battery", level="OK"))

        def quiet():
            world.fleet.robots["husky"].diagnostics_topic = None  # its diagnostics node died

        world.call(quiet)
        page.wait_for_selector(ROW.format(name="battery", level="STALE"), timeout=15000)
        assert "not heard from" in page.locator(ROW.format(name="battery", level="STALE")).inner_text()


@pytest.mark.parametrize(
    "name", ["turtlebot", "husky"]
)  # a differential drive; a skid-steer with a move_base
def test_arrow_down_drives_straight_back_and_the_plots_tick_at_sane_intervals(
    login, operator, live_url, fleet_admin, name
):
    with registered_world(fleet_admin, keys=(name,)) as world:
        robot = Robot.objects.get(name=name)
        page = login(operator)
        page.goto(f"{live_url}/robots/{robot.pk}/")
        page.wait_for_selector("#conn[data-state=live]")
        start = world.pose(name)
        page.locator("#teleop").focus()
        page.keyboard.down("ArrowDown")
        time.sleep(1.5)
        page.keyboard.up("ArrowDown")
        wait_for(lambda: at_rest(world, name), timeout=10, what=f"{name} stops when the key is released")
        end = world.pose(name)

        turned = math.degrees(abs(math.remainder(end[2] - start[2], math.tau)))
        heading = (math.cos(start[2]), math.sin(start[2]))
        along = (end[0] - start[0]) * heading[0] + (end[1] - start[1]) * heading[1]
        across = -(end[0] - start[0]) * heading[1] + (end[1] - start[1]) * heading[0]
        assert turned < 2.0, f"ArrowDown turned the robot by {turned:.1f}°"
        assert along < -0.1, f"ArrowDown did not drive back (moved {along:+.2f} m along its heading)"
        assert abs(across) < 0.05, f"ArrowDown drifted sideways {across:+.2f} m"

        page.wait_for_function("() => window.fleet.plots.series.t.length > 10")
        page.wait_for_timeout(700)  # the plots redraw at most twice a second
        ticks = page.evaluate("() => window.fleet.plots.speed.axes[0]._splits")
        gaps = {round(b - a, 3) for a, b in itertools.pairwise(ticks)}
        assert ticks and gaps and min(gaps) >= 15, f"time axis ticks every {sorted(gaps)} s"
        span = page.evaluate("() => { const x = window.fleet.plots.speed.scales.x; return x.max - x.min; }")
        assert span == pytest.approx(120, abs=1)  # the plot's window is two minutes from the first point
