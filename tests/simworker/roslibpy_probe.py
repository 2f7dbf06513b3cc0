"""Drive simulated endpoints with roslibpy (a real rosbridge client) and print what it saw as JSON.

Run in its own process: roslibpy's transports are process-wide (Twisted's reactor cannot restart and a
process that imported daphne is already Twisted), so the tests never import roslibpy themselves.
Usage: python roslibpy_probe.py '<json list of {url, cmd, odom, param, speed, ros2}>'
"""

import json
import sys
import threading
import time
import traceback

import roslibpy

DRIVE_SECONDS = 1.5


def connect(url: str) -> roslibpy.Ros:
    """Connect with the asyncio transport (one Ros at a time: the shared loop starts lazily)."""
    host, port = url.removeprefix("ws://").rsplit(":", 1)
    ros = roslibpy.Ros(host, int(port), transport="asyncio")
    ros.run(timeout=5)
    return ros


def probe(ros: roslibpy.Ros, case: dict, out: dict) -> None:
    """Discover the endpoint's graph, then drive the robot and record its odometry."""
    out["topics"] = ros.get_topics()
    out["nodes"] = ros.get_nodes()
    out["services"] = ros.get_services()
    out["cmd_type"] = ros.get_topic_type(case["cmd"])
    out["odom_type"] = ros.get_topic_type(case["odom"])
    out["node_details"] = ros.get_node_details(out["nodes"][0])
    out["params"] = ros.get_params()
    out["description"] = roslibpy.Param(ros, case["param"]).get(timeout=5)
    odom = []
    listener = roslibpy.Topic(ros, case["odom"], case["odom_msg_type"])
    listener.subscribe(odom.append)
    cmd = roslibpy.Topic(ros, case["cmd"], out["cmd_type"])
    cmd.advertise()
    twist = {"linear": {"x": case["speed"], "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
    end = time.time() + DRIVE_SECONDS
    while time.time() < end:
        cmd.publish(roslibpy.Message(twist))
        time.sleep(0.1)
    time.sleep(1.2)  # the command times out; the robot brakes
    listener.unsubscribe()
    out["odom"] = list(odom)
    ros.close()


def main() -> None:
    cases = json.loads(sys.argv[1])
    results = [{} for _ in cases]
    clients = [connect(c["url"]) for c in cases]
    threads = [
        threading.Thread(target=_guard, args=(ros, c, r))
        for ros, c, r in zip(clients, cases, results, strict=True)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    print(json.dumps(results))


def _guard(ros: roslibpy.Ros, case: dict, out: dict) -> None:
    try:
        probe(ros, case, out)
    except Exception as exc:  # reported to the test, which fails with the text
        out["error"] = f"{type(exc).__name__}: {exc} {traceback.format_exc()[-600:]}"


if __name__ == "__main__":
    main()
