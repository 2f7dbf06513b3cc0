"""The pose ticks as the browsers get them (portal.fanout.encode): rows under the tick's fields, made back into
poses by decode() here and by static/fleet/live.js in the page, the two agreeing."""

import json

import pytest

import live
from portal import fanout

TICK = [
    {"id": 1, "x": 1.5, "y": -2.25, "yaw": 3.1, "v": 0.2, "w": 0.0, "t": 1795852345.125, "battery": 87.5},
    {"id": 2, "x": 0.0, "y": 0.0, "yaw": 0.0, "v": 0.0, "w": 0.5, "t": 1795852345.05, "rtt": 1.2},
    {
        "id": 3,
        "fault": "x is NaN",
        "fault_since": 1795852340.5,
    },  # refused from its first message: no pose yet
]


def test_a_tick_goes_as_rows_under_its_fields_and_comes_back_as_it_was():
    text = fanout.encode(TICK)
    message = json.loads(text)
    assert message["fields"] == [
        "id",
        "x",
        "y",
        "yaw",
        "v",
        "w",
        "t",
        "battery",
        "rtt",
        "fault",
        "fault_since",
    ]
    assert message["rows"][0][:7] == [1, 1.5, -2.25, 3.1, 0.2, 0.0, 75]  # t: ms after the tick's `at`
    fleet = [
        {**TICK[0], "id": n, "x": 0.001 * n} for n in range(100)
    ]  # a fleet's tick: half the text or less
    assert len(fanout.encode(fleet)) < len(json.dumps(live.poses(fleet))) / 2
    back = fanout.decode(message)
    assert [{k: v for k, v in p.items() if k != "t"} for p in back] == [
        {k: v for k, v in p.items() if k != "t"} for p in TICK
    ]
    assert [p.get("t") for p in back] == [
        pytest.approx(p.get("t"), abs=1e-3) if "t" in p else None for p in TICK
    ]


def test_the_browser_makes_the_same_poses_of_a_tick_as_decode(tmp_path):
    """static/fleet/live.js's unpack and poseRows, run by node on encode()'s text: the page reads what the server
    meant."""
    import shutil
    import subprocess
    from pathlib import Path

    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (the browser's decoder is run by node here)")
    live_js = Path(__file__).resolve().parents[2] / "static" / "fleet" / "live.js"
    script = (  # the tick inside a batch frame, as a burst would bring it: unpack, then poseRows
        f"import {{ poseRows, unpack }} from {json.dumps(live_js.as_uri())};\n"
        "let text = ''; process.stdin.on('data', (d) => { text += d; });\n"
        "process.stdin.on('end', () => {\n"
        "  const [tick] = unpack({ type: 'batch', messages: [JSON.parse(text)] });\n"
        "  console.log(JSON.stringify(poseRows(tick)));\n"
        "});\n"
    )
    (tmp_path / "decode.mjs").write_text(script)
    text = fanout.encode(TICK)
    out = subprocess.run(
        [node, str(tmp_path / "decode.mjs")], input=text, capture_output=True, text=True, timeout=30
    )
    assert out.returncode == 0, out.stderr
    made = json.loads(out.stdout)
    decoded = fanout.decode(json.loads(text))
    assert len(made) == len(decoded) == 3
    for browser, server in zip(made, decoded, strict=True):
        assert browser.keys() == server.keys()
        assert all(browser[k] == pytest.approx(server[k]) for k in server)
