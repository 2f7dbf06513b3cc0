"""A Content-Security-Policy on every page, with no inline script or style left that would need 'unsafe-inline'
(the rest of the browser suite fails on any violation: tests/portal/conftest.py, `browser`)."""

import re

import pytest

from tests.portal.pages import every_page

INLINE_SCRIPT = re.compile(r"<script(?![^>]*\bsrc=)(?![^>]*application/json)[^>]*>", re.I)
INLINE_STYLE = re.compile(r"<style\b|\sstyle=\"|\son[a-z]+=\"", re.I)


def test_every_page_sends_the_policy_and_has_no_inline_code(client_for, fleet_admin, fleet, tmp_path):
    client = client_for(fleet_admin)
    for name, path in every_page(fleet["turtlebot"], tmp_path).items():
        response = client.get(path)
        assert response.status_code == 200, name
        policy = response.headers["Content-Security-Policy"]
        assert "script-src 'self'" in policy and "unsafe-inline" not in policy, name
        assert "frame-ancestors 'none'" in policy and "object-src 'none'" in policy, name
        assert response.headers["X-Content-Type-Options"] == "nosniff", name
        assert response.headers["Referrer-Policy"] == "same-origin", name
        assert response.headers["X-Frame-Options"] == "DENY", name
        html = response.content.decode()
        assert not INLINE_SCRIPT.findall(html), f"{name}: {INLINE_SCRIPT.findall(html)}"
        if name not in {"api-docs", "admin"}:  # theirs: Swagger UI's and Django's own templates
            assert not INLINE_STYLE.findall(html), f"{name}: {INLINE_STYLE.findall(html)}"


def test_refused_and_anonymous_answers_carry_the_policy_too(client):
    for response in (client.get("/login/"), client.get("/api/robots"), client.get("/")):
        assert "default-src 'self'" in response.headers["Content-Security-Policy"]


@pytest.mark.browser
@pytest.mark.timeout(180)
def test_every_page_runs_under_the_policy_and_inline_code_is_refused(
    login, browser, fleet_admin, fleet, live_url, tmp_path
):
    """Each page loads with no violation (the fixture fails on any); a script someone injects does not run."""
    pages = every_page(fleet["turtlebot"], tmp_path)
    page = login(fleet_admin)
    for name, path in pages.items():
        response = page.goto(f"{live_url}{path}")
        assert "script-src 'self'" in response.headers["content-security-policy"], name
        page.wait_for_load_state("load")
    page.goto(f"{live_url}/")
    page.wait_for_selector(
        "#conn[data-state=live]"
    )  # the dashboard's module script ran and opened its socket
    page.evaluate("""() => { const s = document.createElement("script");
        s.textContent = "window.__injected = true"; document.body.append(s); }""")
    page.wait_for_timeout(200)
    assert page.evaluate("window.__injected") is None
    assert any("script-src" in words for words in browser.csp_violations)
    browser.csp_violations.clear()  # the one violation this test made on purpose
