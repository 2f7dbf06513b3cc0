"""Fixtures for the portal's tests: a small fleet on a small map."""

import pytest

from execution.models import TimeSlot
from fleet.testrun import chromium_path
from places.models import Location, Map
from robots.models import Binding, Robot
from simworker.testing import bound_socket, free_port


def slot_hours() -> tuple[str, str]:
    """A two-hour time slot well away from now: a robot in its slot is refused other work, so a fixed slot made
    the tests that instruct the fleet fail during its hours (a CI run at 08:11 did, with "08:00-10:00")."""
    from django.utils import timezone

    start = 14 if timezone.localtime().hour < 8 else 2
    return f"{start:02d}:00", f"{start + 2:02d}:00"


@pytest.fixture
def small_map(db):
    """A 20 x 20 cell map (1 m x 1 m at 5 cm) with a wall row and two locations."""
    cells = bytearray(400)
    cells[200:220] = bytes([100]) * 20
    grid = Map.objects.create(name="tiny", resolution=0.05, width=20, height=20, data=bytes(cells))
    Location.objects.create(map=grid, name="A", x=0.2, y=0.2)
    Location.objects.create(map=grid, name="B", x=0.8, y=0.8, kind=Location.Kind.ROOM)
    return grid


@pytest.fixture
def fleet(db, small_map):
    """Two robots: a turtlebot with bindings (one needing a person) and a husky, plus a time slot."""
    turtlebot = Robot.objects.create(
        name="turtlebot", model="turtlebot3_burger", endpoint="ws://127.0.0.1:9091",
        link_status=Robot.Link.ONLINE, state=Robot.State.READY, start_pose=[0.5, 0.5, 0.0],
        footprint=[[0.1, 0.1], [-0.1, 0.1], [-0.1, -0.1], [0.1, -0.1]], description={"wheels": 2},
    )  # fmt: skip
    husky = Robot.objects.create(name="husky", model="husky", endpoint="ws://127.0.0.1:9092", max_linear=1.0)
    turtlebot.topics.create(name="/cmd_vel", type="geometry_msgs/Twist")
    turtlebot.topics.create(name="/odom", type="nav_msgs/Odometry")
    turtlebot.topics.create(name="/odom_raw", type="nav_msgs/Odometry")
    Binding.objects.create(
        robot=turtlebot, action="move", target="/cmd_vel", message_type="geometry_msgs/Twist", how="exact",
        confidence=1.0,
    )  # fmt: skip
    Binding.objects.create(
        robot=turtlebot, action="odometry", needs_user=True,
        candidates=[
            {"target": "/odom", "type": "nav_msgs/Odometry", "score": 0.5, "how": "pattern"},
            {"target": "/odom_raw", "type": "nav_msgs/Odometry", "score": 0.5, "how": "pattern"},
        ],
    )  # fmt: skip
    start, end = slot_hours()
    TimeSlot.objects.create(
        robot=turtlebot, start=start, end=end, goal=small_map.locations.get(name="A"), task="rotate(5)"
    )
    return {"turtlebot": turtlebot, "husky": husky}


# --- browser tests: the ASGI app served by uvicorn in a thread of this process, on the test database ---------

CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip


def _fresh_interpreter():
    """The server is a fresh process: forget robots and places an earlier test's database gave the interpreter."""
    from interpreter.service import store

    store.cache_clear()


@pytest.fixture
def live_url(transactional_db, settings):
    """The whole portal (HTTP and WebSockets) on a port bound first; the test's committed rows are what it serves."""
    import threading
    import time
    import uuid

    import uvicorn

    from fleet.asgi import application
    from fleet.websocket import Protocol

    # execution's Redis keys (stop flags live 10 min) must not carry over between runs that reuse robot ids
    settings.FLEET_EXEC_KEY_PREFIX = f"test:portal:{uuid.uuid4().hex[:8]}"
    _fresh_interpreter()
    sock, port = bound_socket()
    config = uvicorn.Config(
        application,
        host="127.0.0.1",
        port=port,
        log_level="warning",
        lifespan="off",
        timeout_graceful_shutdown=3,
        ws=Protocol,  # as every web server of the portal (fleet/websocket.py)
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, name="uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(timeout=10)
    if thread.is_alive():  # a daemon thread still serving at interpreter exit can crash it (uvloop)
        server.force_exit = True
        thread.join(timeout=5)
    if thread.is_alive():
        import faulthandler
        import sys

        faulthandler.dump_traceback(sys.stderr)  # where every thread is: what holds the server up
        raise RuntimeError(f"uvicorn on port {port} did not stop within 15 s of the test's end")


@pytest.fixture
def browser(monkeypatch):
    """Debian's chromium, headless, driven by Playwright (skipped where it is not installed)."""
    path = chromium_path()
    if path is None:
        pytest.skip("no chromium at /usr/bin/chromium (set FLEET_CHROMIUM)")
    # Playwright's sync API keeps an event loop in this thread; the test's own ORM calls are still sync.
    monkeypatch.setenv("DJANGO_ALLOW_ASYNC_UNSAFE", "true")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=path, args=CHROMIUM_ARGS)
        violations = _watch_csp(chromium)
        yield chromium
        chromium.close()
    assert not violations, f"Content-Security-Policy violations: {violations}"


# Every page of every browser test reports what the Content-Security-Policy refused (the event fires in the page;
# the binding carries it out across navigations); the browser fixture fails the test on any.
CSP_LISTENER = """document.addEventListener("securitypolicyviolation", (e) => window.__cspViolation(
  `${e.violatedDirective} blocked ${e.blockedURI || "inline"} at ${e.sourceFile || e.documentURI}:${e.lineNumber}`));"""


def _watch_csp(chromium) -> list[str]:
    """Patch the browser's new_context so that each context reports CSP violations into the returned list."""
    violations: list[str] = []
    new_context = chromium.new_context

    def watched(**options):
        context = new_context(**options)
        context.expose_binding("__cspViolation", lambda _source, words: violations.append(words))
        context.add_init_script(CSP_LISTENER)
        return context

    chromium.new_context = watched
    chromium.csp_violations = violations  # a test that makes one on purpose clears it
    return violations


@pytest.fixture
def login(browser, live_url):
    """Open a fresh browser context logged in as the given user (through the login form); return its page."""
    from tests.conftest import PASSWORD

    def _login(user, width: int = 1280, height: int = 900):
        context = browser.new_context(viewport={"width": width, "height": height})
        page = context.new_page()
        page.set_default_timeout(15000)
        page.goto(f"{live_url}/login/")
        page.get_by_label("Username").fill(user.username)
        page.get_by_label("Password").fill(PASSWORD)
        page.get_by_role("button", name="Log in").click()
        page.wait_for_url(f"{live_url}/")
        return page

    return _login


@pytest.fixture
def seeded_terms(transactional_db):
    """The interpreter's seed terms, which a flush after an earlier transactional test has wiped."""
    import importlib

    from django.apps import apps

    migration = importlib.import_module("interpreter.migrations.0002_seed_terms")
    migration.seed(apps, None)
    _fresh_interpreter()


# --- the role matrix and the API fuzzing: a world whose robot nothing can reach ---------------------------


@pytest.fixture
def world(db):
    """A robot (its endpoint a closed port: nothing is reached), a binding to choose, a slot, a location."""
    from execution.models import TimeSlot
    from places.models import Location, Map
    from robots.models import Binding, Robot

    grid = Map.objects.create(name="tiny", resolution=0.05, width=4, height=4, data=bytes(16))
    place = Location.objects.create(map=grid, name="A", x=0.1, y=0.1)
    robot = Robot.objects.create(
        name="probe", endpoint=f"ws://127.0.0.1:{free_port()}", link_status=Robot.Link.ONLINE,
        state=Robot.State.READY,
    )  # fmt: skip
    robot.topics.create(name="/cmd_vel", type="geometry_msgs/Twist")
    Binding.objects.create(robot=robot, action="move", target="/cmd_vel", message_type="geometry_msgs/Twist")
    binding = Binding.objects.create(
        robot=robot, action="odometry", needs_user=True, candidates=[{"target": "/odom", "type": "x"}]
    )
    start, end = slot_hours()
    slot = TimeSlot.objects.create(robot=robot, start=start, end=end, goal=place, task="")
    return {"robot": robot, "binding": binding, "slot": slot, "location": place}


@pytest.fixture
def recorded_control(monkeypatch):
    """execution.control with its checks real and its effects recorded: no robot is driven or stopped."""
    import importlib
    import sys

    import execution

    real = importlib.import_module("execution.control")
    calls = []

    class Control:
        teleop_grants = staticmethod(real.teleop_grants)
        GRANT_S = real.GRANT_S

        @staticmethod
        def stop(robots, user, **kwargs):
            calls.append(("stop", user.username))
            return {getattr(robot, "name", robot): "stopped" for robot in robots}

        @staticmethod
        def teleop_with(grant, user, linear, angular):
            calls.append(("teleop", user.username))
            return grant.clamp(linear, angular)

        @staticmethod
        async def publish_teleop(grant, linear, angular):
            calls.append(("teleop", grant.robot_name))
            return grant.clamp(linear, angular)

        @staticmethod
        def audit_teleops(user, batch):
            return None

    fast_stop = importlib.import_module("execution.fast_stop")
    monkeypatch.setattr(
        fast_stop, "stop_blocking", lambda *args, **kwargs: calls.append(("zeros", args)) or 0
    )
    monkeypatch.setitem(sys.modules, "execution.control", Control)
    monkeypatch.setattr(execution, "control", Control, raising=False)
    return calls


@pytest.fixture
def seeded_words(db):
    """The interpreter's seed terms in this test's transaction (a transactional test before may have flushed
    them), and an interpreter that reads them afresh."""
    import importlib

    from django.apps import apps

    importlib.import_module("interpreter.migrations.0002_seed_terms").seed(apps, None)
    _fresh_interpreter()
