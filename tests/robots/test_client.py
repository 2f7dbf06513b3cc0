"""The asyncio rosbridge client against a rosbridge server (the simulator's), and against things that are not."""

import asyncio
import socket

import pytest

from robots.rosbridge import (
    LinkDown,
    NotRosbridgeError,
    RosbridgeClient,
    RosbridgeTimeout,
    ServiceError,
    UnreachableError,
)
from tests.robots.fakes import HttpServer, OddServer, free_port

pytestmark = [pytest.mark.timeout(30), pytest.mark.asyncio]


async def test_call_service_returns_the_values(endpoint):
    ep = endpoint()
    async with RosbridgeClient(ep.url) as client:
        reply = await client.call_service("/rosapi/topic_type", {"topic": "/cmd_vel"})
    assert reply == {"type": "geometry_msgs/Twist"}


async def test_failed_call_raises_service_error_with_the_servers_text(endpoint):
    ep = endpoint()
    async with RosbridgeClient(ep.url) as client:
        with pytest.raises(ServiceError, match="Service /nope does not exist"):
            await client.call_service("/nope")


async def test_unreachable_endpoint_is_a_one_line_error():
    client = RosbridgeClient(f"ws://127.0.0.1:{free_port()}")
    with pytest.raises(UnreachableError, match="unreachable") as info:
        await client.connect()
    assert "\n" not in str(info.value)


async def test_http_server_is_not_rosbridge():
    with HttpServer() as http, pytest.raises(NotRosbridgeError, match="HTTP 200"):
        await RosbridgeClient(http.url).connect()


async def test_garbage_answers_fail_the_call_at_once():
    with OddServer("garbage") as odd:
        async with RosbridgeClient(odd.url, call_timeout=10) as client:
            with pytest.raises(NotRosbridgeError, match="not JSON"):
                await client.call_service("/rosapi/topics")


async def test_silent_server_times_out():
    with OddServer("silent") as odd:
        async with RosbridgeClient(odd.url, call_timeout=0.3) as client:
            with pytest.raises(RosbridgeTimeout, match=r"no answer to /rosapi/topics within 0\.3 s"):
                await client.call_service("/rosapi/topics")
            with pytest.raises(TimeoutError):  # RosbridgeTimeout is a TimeoutError
                await client.call_service("/rosapi/nodes")


async def test_publish_advertises_once_and_reaches_subscribers(endpoint):
    ep = endpoint()
    got = asyncio.Queue()
    async with RosbridgeClient(ep.url) as listener, RosbridgeClient(ep.url) as talker:
        await listener.subscribe("/cmd_vel", "geometry_msgs/Twist", got.put_nowait)
        await asyncio.sleep(0.05)
        for x in (0.1, 0.2):
            await talker.publish("/cmd_vel", {"linear": {"x": x}}, "geometry_msgs/Twist")
        first, second = await asyncio.wait_for(got.get(), 2), await asyncio.wait_for(got.get(), 2)
    assert (first["linear"]["x"], second["linear"]["x"]) == (0.1, 0.2)


async def test_frames_keep_their_order_when_the_link_backs_up_and_drains(endpoint):
    """An idle link's frame is written at once; one that finds the link backed up waits in websockets' send:
    the listener gets them all, in the order they were published."""
    ep = endpoint()
    got, idle_before = [], []
    padding = "x" * 100_000
    async with RosbridgeClient(ep.url) as listener, RosbridgeClient(ep.url) as talker:
        await listener.subscribe("/chatter", "std_msgs/String", got.append)
        sock = talker._ws.transport.get_extra_info("socket")
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)  # a small buffer: big frames back it up
        await asyncio.sleep(0.05)
        for i in range(100):  # 100 KB each, back to back: the link backs up
            idle_before.append(talker.idle)
            await talker.publish("/chatter", {"data": f"{i} {padding}"}, "std_msgs/String")
        for i in range(100, 200):  # small ones, each once the link has drained
            for _ in range(200):  # bounded: 10 MB leave loopback well within 10 s
                if talker.idle:
                    break
                await asyncio.sleep(0.05)
            idle_before.append(talker.idle)
            await talker.publish("/chatter", {"data": f"{i}"}, "std_msgs/String")
        for _ in range(200):
            if len(got) == 200:
                break
            await asyncio.sleep(0.05)
    assert [int(m["data"].split()[0]) for m in got] == list(range(200))
    assert idle_before.count(False) > 50 and idle_before[100:] == [True] * 100  # both ways of writing taken


async def test_unsubscribe_stops_messages(endpoint):
    ep = endpoint()
    got = []
    async with RosbridgeClient(ep.url) as listener, RosbridgeClient(ep.url) as talker:
        sub = await listener.subscribe("/cmd_vel", "geometry_msgs/Twist", got.append)
        await asyncio.sleep(0.05)
        await listener.unsubscribe(sub)
        await asyncio.sleep(0.05)
        await talker.publish("/cmd_vel", {"linear": {"x": 1.0}}, "geometry_msgs/Twist")
        await asyncio.sleep(0.2)
    assert got == []


async def test_reconnects_after_restart_and_resubscribes(endpoint):
    ep = endpoint()
    events, got = [], asyncio.Queue()
    client = RosbridgeClient(ep.url, ping_interval=1.0, max_backoff=0.4)
    client.on_link(lambda up, reason: events.append(up))
    await client.start()
    assert await client.wait_connected(3)
    await client.subscribe("/cmd_vel", "geometry_msgs/Twist", got.put_nowait)
    ep.stop()
    for _ in range(100):
        if events[-1] is False:
            break
        await asyncio.sleep(0.02)
    with pytest.raises(LinkDown):
        await client.call_service("/rosapi/nodes")
    ep.start()
    assert await client.wait_connected(5)
    async with RosbridgeClient(ep.url) as talker:
        await asyncio.sleep(0.1)
        await talker.publish("/cmd_vel", {"linear": {"x": 0.3}}, "geometry_msgs/Twist")
        msg = await asyncio.wait_for(got.get(), 3)
    await client.close()
    assert events == [True, False, True]
    assert msg["linear"]["x"] == 0.3


async def test_ros2_action_goal_gets_its_result(paper_world):
    async with RosbridgeClient(paper_world.urls["tb3_nav2"]) as client:
        goal = await client.send_action_goal(
            "/navigate_to_pose",
            "nav2_msgs/action/NavigateToPose",
            {"pose": {"header": {"frame_id": "map"}, "pose": {"position": {"x": 5.0, "y": 5.0}}}},
        )
        await client.cancel_action_goal(goal)
        result = await goal.wait(5)
    assert result["status"] in (5, 6)  # canceled (or aborted if it could not start)


async def test_a_kept_link_lets_its_loop_shut_down(endpoint):
    """A start()ed client nobody closed (a web process's links at shutdown) must not hold asyncio.run open."""
    import threading

    ep = endpoint()
    connected = []

    async def serve_and_leave():
        client = RosbridgeClient(ep.url, ping_interval=1.0)
        await client.start()
        connected.append(await client.wait_connected(3))

    runner = threading.Thread(target=asyncio.run, args=(serve_and_leave(),), daemon=True)
    runner.start()
    await asyncio.to_thread(runner.join, 5)  # asyncio.run cancels the supervisor on the way out
    assert connected == [True]
    assert not runner.is_alive(), "the reconnect loop swallowed its own cancellation"


async def test_a_link_is_idle_only_while_connected_with_nothing_left_to_write(endpoint):
    """What a held button's repeat asks before it publishes without a task of its own (execution.held_teleop)."""
    ep = endpoint()
    client = RosbridgeClient(ep.url, ping_interval=None)
    assert not client.idle  # not connected
    async with client:
        assert client.idle
        await client.publish("/cmd_vel", {"linear": {"x": 0.1}}, "geometry_msgs/Twist")
        for _ in range(50):  # bounded: the frame leaves at once on loopback
            if client.idle:
                break
            await asyncio.sleep(0.01)
        assert client.idle
    assert not client.idle  # closed


async def _serve(handler):
    """A bare WebSocket server on a free port of 127.0.0.1 (its handler decides what the endpoint does)."""
    from websockets.asyncio.server import serve

    port = free_port()
    return await serve(handler, "127.0.0.1", port, ping_interval=None), f"ws://127.0.0.1:{port}"


async def test_a_link_that_streams_faster_than_it_is_read_is_not_closed_as_dead():
    """A process behind on its frames is slow, not cut off: the pong of its keepalive is read with the next chunk
    of the stream (websockets parses a chunk at once, however many messages wait for the reader), so the link
    stays up while the frames queue. (A guard: checked against the 1,000-robot cluster's "link lost", which
    this did not reproduce.)"""
    import time

    frame = '{"op":"publish","topic":"/odom","msg":{"seq":1}}'

    async def stream(ws):
        for sent in range(
            10_000
        ):  # ~1,000 a second (under the flood limit), three times what the reader takes
            await ws.send(frame)
            if sent % 10 == 9:
                await asyncio.sleep(0.01)

    server, url = await _serve(stream)
    events, read = [], []
    client = RosbridgeClient(url, ping_interval=0.3, ping_timeout=0.3, max_backoff=0.2)
    client.on_link(lambda up, reason: events.append((up, reason)))

    def slow(message):  # 3 ms a frame: the pong of each ping waits behind seconds of frames
        time.sleep(0.003)
        read.append(message)

    try:
        await client.start()
        assert await client.wait_connected(3)
        await client.subscribe("/odom", "nav_msgs/Odometry", slow)
        await asyncio.sleep(2.5)  # eight keepalive periods
    finally:
        await client.close()
        server.close()
    assert events == [(True, "connected")]
    assert len(read) > 100


async def test_an_endpoint_that_stops_answering_is_closed_saying_so():
    """An endpoint that reads nothing more (its process stopped, its network cut, or its reader wedged: a command
    would not reach it) answers no ping: the link is closed within the keepalive's period and timeout, and its
    reason says so, not "connection lost (no close frame)"."""
    over = asyncio.Event()

    async def freeze(ws):
        ws.transport.pause_reading()  # reads nothing from now on: no ping is answered
        await asyncio.wait_for(over.wait(), 10)

    server, url = await _serve(freeze)
    events = []
    client = RosbridgeClient(url, ping_interval=0.3, ping_timeout=0.3, max_backoff=5.0)
    client.on_link(lambda up, reason: events.append((up, reason)))
    try:
        await client.start()
        assert await client.wait_connected(3)
        for _ in range(100):  # bounded: 0.3 + 0.3 s, then the close
            if len(events) > 1:
                break
            await asyncio.sleep(0.05)
    finally:
        over.set()
        await client.close()
        server.close()
    assert events[:2] == [(True, "connected"), (False, "no answer to a keepalive ping within 0.3 s")]


async def test_the_links_processs_link_to_an_endpoint_that_answers_seconds_late_stays_up():
    """A busy endpoint (a saturated machine) answers the links process's pings late: its link stays up, and its
    robots online, while the pong comes within PING_TIMEOUT_S (at 1 s, 1,000 robots were said offline)."""
    from robots.links import PING_TIMEOUT_S, liveness_client

    assert PING_TIMEOUT_S > 2.5
    over = asyncio.Event()

    async def late(ws):
        ws.transport.pause_reading()  # the first pings wait unread for 2.5 s, then are answered
        await asyncio.sleep(2.5)
        ws.transport.resume_reading()
        await asyncio.wait_for(over.wait(), 10)

    server, url = await _serve(late)
    events = []
    client = liveness_client(url)
    client.on_link(lambda up, reason: events.append((up, reason)))
    try:
        await client.start()
        assert await client.wait_connected(3)
        await asyncio.sleep(4.0)
        assert client.is_connected
    finally:
        over.set()
        await client.close()
        server.close()
    assert events == [(True, "connected")]
