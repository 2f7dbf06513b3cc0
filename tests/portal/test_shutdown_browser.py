"""Ctrl-C of `make run` with pages open: the web server's graceful shutdown ends every page's sockets in time, so
uvicorn never says "Cancel N running task(s), timeout graceful shutdown exceeded"."""

import logging
import threading
import time

import pytest

from robots.models import Robot
from simworker.testing import bound_socket
from tests.portal.test_telemetry_browser import registered_world

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.timeout(180)]

GRACE_S = 5  # what fleet/run.py gives uvicorn (--timeout-graceful-shutdown 5)


class Said(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.lines: list[str] = []

    def emit(self, record) -> None:
        self.lines.append(record.getMessage())


def serve(application):
    """uvicorn in a thread on a socket bound first (simworker.testing.bound_socket); (server, thread, port)."""
    import uvicorn

    sock, port = bound_socket()
    config = uvicorn.Config(
        application, host="127.0.0.1", port=port, log_level="info", lifespan="on",
        timeout_graceful_shutdown=GRACE_S,
    )  # fmt: skip
    server = uvicorn.Server(config)
    thread = threading.Thread(
        target=server.run, kwargs={"sockets": [sock]}, name="uvicorn-shutdown", daemon=True
    )
    thread.start()
    deadline = time.monotonic() + 15
    while not server.started:
        assert time.monotonic() < deadline and thread.is_alive(), "uvicorn did not start"
        time.sleep(0.05)
    return server, thread, port


def test_open_pages_do_not_hold_up_the_servers_shutdown(
    transactional_db, settings, browser, operator, fleet_admin, monkeypatch
):
    import uuid

    from fleet.asgi import application
    from tests.conftest import PASSWORD

    settings.FLEET_EXEC_KEY_PREFIX = f"test:shutdown:{uuid.uuid4().hex[:8]}"
    said = Said()
    with registered_world(fleet_admin, keys=("husky",)):
        server, thread, port = serve(application)
        url = f"http://127.0.0.1:{port}"
        logging.getLogger("uvicorn.error").addHandler(said)  # after uvicorn configured its logging
        try:
            context = browser.new_context()
            page = context.new_page()
            page.goto(f"{url}/login/")
            page.get_by_label("Username").fill(operator.username)
            page.get_by_label("Password").fill(PASSWORD)
            page.get_by_role("button", name="Log in").click()
            page.wait_for_url(f"{url}/")
            page.wait_for_selector("#conn[data-state=live]")
            robot_page = context.new_page()
            robot_page.goto(f"{url}/robots/{Robot.objects.get(name='husky').pk}/")
            robot_page.wait_for_selector("#conn[data-state=live]")
            robot_page.wait_for_selector("#diagnostics tr[data-level]")  # its feeds follow the robot
            time.sleep(1)
        finally:
            started = time.monotonic()
            server.should_exit = True
            thread.join(timeout=GRACE_S + 10)
            took = time.monotonic() - started
            logging.getLogger("uvicorn.error").removeHandler(said)
    assert not thread.is_alive()
    assert not [line for line in said.lines if "graceful shutdown exceeded" in line], said.lines
    assert took < GRACE_S, f"the shutdown took {took:.1f} s"
