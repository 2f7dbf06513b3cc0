"""The npm roslib client (2.1.0, ESM, on Node) discovers and drives the TurtleBot3 endpoint.

Skipped where node or the installed package is missing (`npm install` in tests/simworker/js).
"""

import json
import shutil
import subprocess
from pathlib import Path

import pytest

JS = Path(__file__).with_name("js")
pytestmark = [
    pytest.mark.timeout(60),
    pytest.mark.skipif(
        shutil.which("node") is None or not (JS / "node_modules" / "roslib").exists(),
        reason="node or npm roslib not installed (cd tests/simworker/js && npm install)",
    ),
]


def test_roslibjs_lists_the_graph_and_drives_the_turtlebot(world):
    out = subprocess.run(
        ["node", "probe.mjs", world.urls["turtlebot"], "/cmd_vel", "/odom", "0.2"],
        cwd=JS,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout)
    assert {"/cmd_vel", "/odom", "/scan"} <= set(seen["topics"]["topics"])
    assert seen["topics"]["types"][seen["topics"]["topics"].index("/odom")] == "nav_msgs/Odometry"
    assert "/turtlebot3_core" in seen["nodes"] and "/rosapi/get_param" in seen["services"]
    assert 'joint name="wheel_left_joint"' in seen["description"]
    assert max(seen["speeds"]) == pytest.approx(0.2, abs=0.01)
