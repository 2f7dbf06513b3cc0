"""Screenshots at 1280 x 800 of the pages without a map (history, schedules, experiments, recordings and a replay,
audit, registration, alerts, API docs), none wider than the window (FLEET_SCREENSHOTS=1 to write them)."""

import time

from audit.records import record
from recordings.mcapfile import RecordingWriter
from recordings.models import Recording
from tests.portal.demo import SCREENSHOT_MARKS, SCREENSHOTS, demo_urls, demo_world

OUT = SCREENSHOTS
pytestmark = SCREENSHOT_MARKS


def _recording(tmp_path) -> Recording:
    """Three seconds of every robot of the paper world leaving its start pose (0.3 m/s along its heading)."""
    import math

    from fleetcore.world import load_world

    path = tmp_path / "shot.mcap"
    writer = RecordingWriter(path)
    t0 = time.time()
    for i in range(31):
        for spec in load_world("paper").robots:
            d = 0.03 * i
            writer.pose(
                spec.name,
                spec.x + d * math.cos(spec.yaw),
                spec.y + d * math.sin(spec.yaw),
                spec.yaw,
                t0 + 0.1 * i,
            )
    writer.transition("turtlebot", "ready", "motion", "instruction 1", 1, t0)
    writer.instruction(1, "move turtlebot to B", "succeeded", "", t0 + 3)
    writer.close()
    return Recording.objects.create(
        seconds=3, path=str(path), status="finished", counts={"/fleet/turtlebot/pose": 31}
    )


def test_write_page_screenshots(seeded_terms, login, fleet_admin, live_url, tmp_path, monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    from fleet.celery import app
    from robots.registration import register_endpoints

    monkeypatch.setitem(app.conf, "task_always_eager", True)
    OUT.mkdir(parents=True, exist_ok=True)
    with demo_world() as world, ThreadPoolExecutor(1) as pool:  # registration runs its own event loop
        pool.submit(register_endpoints, demo_urls(world), fleet_admin).result(timeout=60)
        record(fleet_admin, "control.take", "turtlebot", taken_over_from=None, seconds=300)
        _shoot(login(fleet_admin, width=1280, height=800), live_url, _recording(tmp_path))


def _shoot(page, live_url, replay):
    shots = {
        "history": "/history/",
        "schedules": "/schedules/",
        "experiments": "/experiments/",
        "recordings": "/recordings/",
        "replay": f"/recordings/{replay.pk}/",
        "audit": "/audit/",
        "registration": "/register/",
        "alerts": "/alerts/",
        "api-docs": "/api/docs",
    }
    for name, path in shots.items():
        page.goto(f"{live_url}{path}")
        if name == "replay":
            page.wait_for_selector("#replay[data-loaded=true]")
            page.get_by_label("Time in the recording (s)").focus()
            for _ in range(30):
                page.keyboard.press("ArrowRight")
        if name == "api-docs":
            page.wait_for_selector(".swagger-ui .opblock")
        if name == "experiments":
            page.wait_for_selector("#table-3 .uplot")
        assert page.evaluate("document.documentElement.scrollWidth") <= 1280, name
        page.screenshot(path=str(OUT / f"{name}.png"))
    assert all((OUT / f"{name}.png").stat().st_size > 10_000 for name in shots)
