"""Issue 18's small things in a real browser: API docs from local assets only, no connection pill where no
socket is opened, the top bar on one row, and the registration log kept after a registration ends."""

from urllib.parse import urlparse

import pytest

from simworker.testing import free_port

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

NO_SOCKET_PAGES = ("/history/", "/schedules/", "/experiments/", "/audit/", "/alerts/")


def _block_the_network(page) -> list[str]:
    """Abort every request that is not to 127.0.0.1 (as on a machine without internet); return what was tried."""
    refused = []

    def handle(route):
        if urlparse(route.request.url).hostname == "127.0.0.1":
            route.continue_()
        else:
            refused.append(route.request.url)
            route.abort()

    page.context.route("**/*", handle)
    return refused


def test_api_docs_load_with_the_network_blocked(login, viewer, live_url):
    page = login(viewer)
    refused = _block_the_network(page)
    page.get_by_role("link", name="API", exact=True).click()
    page.wait_for_url(f"{live_url}/api/docs")
    # Swagger UI drew the operations of our own schema: its script and styles came from this server
    page.wait_for_selector(".swagger-ui .opblock-summary-path:has-text('/api/instructions')", timeout=20000)
    assert page.locator(".swagger-ui .info .title").inner_text().startswith("Fleet portal API")
    assert refused == []


def test_admin_link_only_for_admins(login, viewer, fleet_admin, live_url):
    page = login(viewer)
    assert page.locator("#admin-link").count() == 0
    admin = login(fleet_admin)
    admin.locator("#admin-link").click()
    admin.wait_for_selector("#site-name")  # Django's admin index


def test_pages_without_a_socket_show_no_pill_and_keep_the_top_bar_on_one_row(login, fleet_admin, live_url):
    """At 1280 px, with the pill on the dashboard and without it elsewhere."""
    page = login(fleet_admin)  # the widest top bar: every link, STOP ALL
    page.wait_for_selector("#conn[data-state=live]")  # the dashboard opens a socket and says so
    for path in ("/", *NO_SOCKET_PAGES):
        page.goto(f"{live_url}{path}")
        assert page.locator("#conn").count() == (path == "/"), path
        brand = page.locator(".topbar .brand").bounding_box()
        stop = page.locator("#stop-all").bounding_box()
        assert abs(stop["y"] - brand["y"]) < brand["height"], f"{path}: STOP ALL wrapped to a second row"
        assert page.evaluate("document.documentElement.scrollWidth") <= 1280, path


def test_registration_log_stays_after_the_registration_ends(login, fleet_admin, live_url):
    page = login(fleet_admin)
    page.goto(f"{live_url}/register/")
    prefill = page.locator("#endpoints").input_value().split()
    assert len(prefill) == 6  # every endpoint of the paper world that carries robots
    page.evaluate("window.__samePage = true")  # gone if the page reloads
    closed = f"ws://127.0.0.1:{free_port()}"  # nothing listens: the registration fails at once
    page.locator("#endpoints").fill(closed)
    page.get_by_role("button", name="Register").click()
    page.wait_for_selector("#reg-progress li >> text=the robots, the choices to make and the records")
    page.wait_for_timeout(2500)  # longer than the old reload's 1.5 s
    assert page.evaluate("window.__samePage === true")
    log = page.locator("#reg-progress").inner_text()
    assert f"{closed}: failed" in log and "registering 1 endpoint" in log
    page.wait_for_selector(f"#reg-records td >> text={closed}")  # the records were refreshed in place


@pytest.mark.parametrize(("width", "height"), [(1024, 768), (1280, 800)])
def test_the_pages_do_not_overflow_sideways(login, fleet_admin, fleet, live_url, tmp_path, width, height):
    from recordings.mcapfile import RecordingWriter
    from recordings.models import Recording

    writer = RecordingWriter(tmp_path / "r.mcap")
    writer.pose("turtlebot", 0.5, 0.5, 0.0, 1.0)
    writer.close()
    replay = Recording.objects.create(seconds=1, path=str(tmp_path / "r.mcap"), status="finished")
    page = login(fleet_admin, width=width, height=height)
    for path in (
        "/register/",
        "/experiments/",
        "/recordings/",
        f"/recordings/{replay.pk}/",
        *NO_SOCKET_PAGES,
    ):
        page.goto(f"{live_url}{path}")
        if path.startswith("/recordings/") and path != "/recordings/":
            page.wait_for_selector("#replay[data-loaded=true]")
        if path == "/experiments/":
            page.wait_for_selector("#table-3 .uplot")
        assert page.evaluate("document.documentElement.scrollWidth") <= width, f"{path} at {width} px"
