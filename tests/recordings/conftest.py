"""The recordings tests use the portal's fixtures (a small fleet, the live server, the browser)."""

from tests.portal.conftest import browser, fleet, live_url, login, small_map  # noqa: F401
