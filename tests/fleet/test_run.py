"""`make run`'s last words: the URL and the login, said once the portal answers (after the workers' start-up)."""

import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from fleet.run import announcement
from simworker.testing import free_port


class _Portal(BaseHTTPRequestHandler):
    def do_GET(self):
        self.send_response(200 if self.path == "/login/" else 404)
        self.end_headers()

    def log_message(self, *args):
        pass


def test_the_url_and_login_come_once_the_portal_answers():
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Portal)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/"
        said = announcement(url, "login: admin / secret", timeout=5)
    finally:
        server.shutdown()
        server.server_close()
    assert f"Fleet portal ready: {url}" in said and "login: admin / secret" in said


def test_a_portal_that_never_answers_is_said_too():
    url = f"http://127.0.0.1:{free_port()}/"
    said = announcement(url, "login: admin / secret", timeout=1)
    assert f"did not answer at {url} within 1 s" in said and "secret" not in said
