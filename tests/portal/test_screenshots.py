"""Screenshots of the dashboard, the console and a robot page for the README (FLEET_SCREENSHOTS=1 to write them)."""

from tests.portal.demo import SCREENSHOT_MARKS, SCREENSHOTS, demo_urls, demo_world, pose_stream

OUT = SCREENSHOTS
pytestmark = SCREENSHOT_MARKS


def test_write_screenshots(seeded_terms, login, fleet_admin, live_url, monkeypatch):
    from fleet.celery import app
    from robots.models import Robot
    from robots.registration import register_endpoints

    monkeypatch.setitem(app.conf, "task_always_eager", True)
    OUT.mkdir(parents=True, exist_ok=True)
    with demo_world() as world:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(1) as pool:  # registration runs its own event loop; Playwright holds this one
            pool.submit(register_endpoints, demo_urls(world), fleet_admin).result(timeout=60)
        with pose_stream():
            page = login(fleet_admin, width=1280, height=860)
            page.wait_for_selector("#conn[data-state=live]")
            page.get_by_label("Instruction", exact=True).fill("move husky to D")
            page.get_by_role("button", name="Send").click()
            page.wait_for_timeout(4000)
            page.screenshot(path=str(OUT / "dashboard.png"))
            page.get_by_label("Instruction", exact=True).fill("fly tiago to the roof")
            page.get_by_role("button", name="Send").click()
            page.wait_for_selector(".parse .question, .parse", timeout=30000)
            page.locator(".console").screenshot(path=str(OUT / "console.png"))
            husky = Robot.objects.get(name="husky")
            page.goto(f"{live_url}/robots/{husky.pk}/")
            page.wait_for_selector("#conn[data-state=live]")
            page.get_by_role("button", name="Take control").click()
            page.wait_for_timeout(1000)
            page.screenshot(path=str(OUT / "robot.png"), full_page=False)
    assert all((OUT / name).stat().st_size > 10_000 for name in ("dashboard.png", "console.png", "robot.png"))
