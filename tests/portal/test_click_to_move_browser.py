"""Click-to-move in a real browser: the page sends robot ids and a location id, never a robot's name as words."""

import json

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90)]


def test_a_location_button_sends_the_selected_robots_by_id(login, operator, fleet, small_map):
    sent = []

    def answer(route):
        """Keep the body the page sent; answer as the API would, without running anything."""
        body = json.loads(route.request.post_data)
        sent.append(body)
        instruction = {
            "id": 1,
            "text": "move robots",
            "status": "queued",
            "type": "I",
            "parse": {},
            "outcome": "",
        }
        route.fulfill(status=201, content_type="application/json", body=json.dumps(instruction))

    page = login(operator)
    page.route("**/api/instructions", answer)
    page.wait_for_selector("#conn[data-state=live]")
    turtlebot = fleet["turtlebot"]
    page.locator(f"#robot-table tr[data-robot-id='{turtlebot.pk}'] input.pick").check()
    page.get_by_role("button", name="B", exact=True).click()
    page.wait_for_function("() => document.querySelector('#progress li') !== null")
    place = small_map.locations.get(name="B")
    assert sent == [{"robot_ids": [turtlebot.pk], "destination": {"location": place.pk}}]
