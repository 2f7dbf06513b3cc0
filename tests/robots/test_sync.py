"""The synchronous facade: one loop thread per process, one shared client per URL, usable from any thread."""

import queue
import threading

import pytest

from robots.rosbridge import LinkDown, ServiceError
from robots.rosbridge.sync import get_client, shutdown

pytestmark = pytest.mark.timeout(30)


def test_shared_client_calls_publishes_and_subscribes_from_threads(endpoint):
    ep = endpoint()
    client = get_client(ep.url)
    assert get_client(ep.url) is client
    assert client.call_service("/rosapi/topic_type", {"topic": "/odom"}) == {"type": "nav_msgs/Odometry"}
    with pytest.raises(ServiceError, match="does not exist"):
        client.call_service("/nope")
    got = queue.Queue()
    sub = client.subscribe("/cmd_vel", "geometry_msgs/Twist", got.put)
    workers = [
        threading.Thread(
            target=client.publish, args=("/cmd_vel", {"linear": {"x": i}}, "geometry_msgs/Twist")
        )
        for i in range(4)
    ]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    xs = sorted(got.get(timeout=5)["linear"]["x"] for _ in range(4))
    client.unsubscribe(sub)
    assert xs == [0, 1, 2, 3]
    client.close()


def test_a_down_endpoint_says_so(endpoint):
    ep = endpoint()
    client = get_client(ep.url)
    ep.stop()
    with pytest.raises(LinkDown, match="not connected"):
        for _ in range(50):  # until the client has noticed the drop
            client.call_service("/rosapi/nodes", timeout=0.2)
    client.close()


def test_closing_lets_the_next_caller_open_a_fresh_link(endpoint):
    ep = endpoint()
    first = get_client(ep.url)
    first.close()
    second = get_client(ep.url)
    assert second is not first
    assert second.call_service("/rosapi/topic_type", {"topic": "/scan"})["type"] == "sensor_msgs/LaserScan"
    second.close()


def test_shutdown_closes_the_links_and_stops_the_loop_thread(endpoint):
    ep = endpoint()
    client = get_client(ep.url)
    loop_thread = client.runner.thread
    shutdown()
    assert not loop_thread.is_alive()
    assert not client.client.is_connected
    fresh = get_client(ep.url)  # the process can still reach robots afterwards, on a new loop
    assert fresh.runner.thread is not loop_thread
    assert fresh.call_service("/rosapi/topic_type", {"topic": "/odom"}) == {"type": "nav_msgs/Odometry"}
    fresh.close()
