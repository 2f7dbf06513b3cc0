"""A recording replays in the portal: the map, each robot where the file says it was at the scrubbed time, the
events up to then."""

import time

import pytest

from recordings.mcapfile import RecordingWriter
from recordings.models import Recording

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90)]


@pytest.fixture
def recorded(tmp_path, fleet):
    """Four seconds of the turtlebot driving from x 0.1 to 0.9 (10 Hz), the husky parked, one state change."""
    path = tmp_path / "drive.mcap"
    writer = RecordingWriter(path)
    t0 = time.time()
    for i in range(41):
        t = t0 + 0.1 * i
        writer.pose("turtlebot", 0.1 + 0.02 * i, 0.5, 0.0, t)
        writer.pose("husky", 0.3, 0.8, 1.5708, t)
        if i == 20:
            writer.transition("turtlebot", "motion", "ready", "arrived", 7, t)
    writer.close()
    return Recording.objects.create(seconds=4, path=str(path), status=Recording.Status.FINISHED)


def _row(page, robot: str) -> list[str]:
    return page.locator(f"#replay-robots tr[data-robot={robot}] td").all_inner_texts()


def test_a_recording_replays_and_the_scrubber_moves_the_robots(login, viewer, recorded, live_url):
    page = login(viewer)
    page.goto(f"{live_url}/recordings/")
    assert page.locator("#conn").count() == 0
    page.locator(f"#recordings tr[data-recording='{recorded.pk}']").get_by_role("link", name="Replay").click()
    page.wait_for_selector("#replay[data-loaded=true]")
    assert _row(page, "turtlebot")[:2] == ["0.10", "0.50"]  # where the file starts
    assert _row(page, "husky") == ["0.30", "0.80", "90"]
    scrub = page.get_by_label("Time in the recording (s)")
    scrub.focus()
    page.keyboard.press("End")  # the slider's own keys, as a person would
    page.wait_for_selector("#replay-time:has-text('4.0 s of 4.0 s')")
    assert _row(page, "turtlebot")[:2] == ["0.90", "0.50"]
    assert (
        page.locator("#replay-events li.current").inner_text().endswith("turtlebot: motion → ready (arrived)")
    )
    page.keyboard.press("Home")
    page.wait_for_selector("#replay-time:has-text('0.0 s of')")
    assert _row(page, "turtlebot")[0] == "0.10"
    assert page.locator("#replay-events li.future").count() == 1  # the state change is still to come
    # dragging the slider to its middle: the turtlebot about halfway (0.5 m at 2 s)
    box = scrub.bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    x = float(_row(page, "turtlebot")[0])
    assert 0.4 <= x <= 0.6
    # the canvas drew the map and the robots: not blank
    painted = page.evaluate(
        "() => { const c = document.getElementById('replay-map'); const d = c.getContext('2d')"
        ".getImageData(0, 0, c.width, c.height).data; let n = 0;"
        " for (let i = 0; i < d.length; i += 4) if (d[i] < 250 || d[i+1] < 250 || d[i+2] < 250) n++; return n; }"
    )
    assert painted > 100
