"""The portal's fixtures (a small fleet, the live server, a logged-in browser) for the alerts' page tests."""

from tests.portal.conftest import browser, fleet, live_url, login, small_map  # noqa: F401
