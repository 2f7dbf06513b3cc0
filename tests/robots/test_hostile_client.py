"""The rosbridge client against a hostile endpoint: no single frame kills its reader or its link."""

import asyncio
import json

import pytest

from robots.rosbridge import BadFrame, FrameTooLarge, NotRosbridgeError, RosbridgeClient, RosbridgeTimeout
from tests.robots.fakes import HostileEndpoint, answer, fragmented, frames, with_id

pytestmark = [pytest.mark.timeout(30), pytest.mark.asyncio]

TOPICS = {"topics": ["/cmd_vel"], "types": ["geometry_msgs/Twist"]}


async def next_message(queue: asyncio.Queue, timeout: float = 3.0):
    return await asyncio.wait_for(queue.get(), timeout)


async def test_a_response_whose_id_is_a_list_is_dropped_and_the_next_call_is_answered():
    answers = iter(
        [
            with_id(lambda i: {"op": "service_response", "id": [i], "values": TOPICS, "result": True}),
            answer(TOPICS),
        ]
    )
    with HostileEndpoint(topics=lambda call: next(answers)(call)) as hostile:
        async with RosbridgeClient(hostile.url, call_timeout=0.3) as client:
            with pytest.raises(
                RosbridgeTimeout
            ):  # its answer could not be told apart: dropped, never matched
                await client.call_service("/rosapi/topics")
            assert client.is_connected
            assert await client.call_service("/rosapi/topics") == TOPICS


async def test_a_fragment_with_a_total_of_abc_fails_only_its_own_call():
    with HostileEndpoint(topics=fragmented(TOPICS, total="abc")) as hostile:
        async with RosbridgeClient(hostile.url) as client:
            with pytest.raises(BadFrame, match="fragment with 'total' = 'abc'"):
                await client.call_service("/rosapi/topics")
            assert client.is_connected
            assert (await client.call_service("/rosapi/nodes")) == {"nodes": ["/base"]}


async def test_fragments_reassemble_and_fragments_above_the_frame_limit_fail_their_call():
    big = {"value": "x" * 300_000}
    with HostileEndpoint(topics=fragmented(TOPICS), get_param=fragmented(big, parts=10)) as hostile:
        async with RosbridgeClient(hostile.url, max_frame_bytes=100_000) as client:
            assert await client.call_service("/rosapi/topics") == TOPICS
            with pytest.raises(FrameTooLarge, match="FLEET_ROBOT_MAX_FRAME_MB"):
                await client.call_service("/rosapi/get_param", {"name": "/big"})
            assert client.is_connected


async def test_a_publish_frame_with_a_list_for_a_topic_is_dropped_and_the_next_one_delivered():
    got = asyncio.Queue()
    with HostileEndpoint() as hostile:
        async with RosbridgeClient(hostile.url) as client:
            await client.subscribe("/odom", "nav_msgs/Odometry", got.put_nowait)
            for bad in (
                {"op": "publish", "topic": ["x"], "msg": {}},
                {"op": "publish", "topic": "/odom", "msg": [1, 2]},
                {"op": "publish", "topic": "/odom"},
                {"op": "action_result", "id": {"a": 1}},
                {"op": "service_response", "id": "x", "result": "yes"},
                {"op": "fragment", "id": 7, "data": "{", "num": 5, "total": float("nan")},
            ):
                hostile.send(json.dumps(bad))
            hostile.publish("/odom", {"twist": {"x": 1}})
            assert await next_message(got) == {"twist": {"x": 1}}
            assert got.empty()  # none of the bad frames reached the callback
            assert client.is_connected


async def test_a_callback_that_raises_does_not_stop_the_next_message():
    got = []

    def fragile(msg):
        got.append(msg)
        raise RuntimeError("a bug in a subscriber")

    with HostileEndpoint() as hostile:
        async with RosbridgeClient(hostile.url) as client:
            await client.subscribe("/odom", "nav_msgs/Odometry", fragile)
            hostile.publish("/odom", {"n": 1})
            hostile.publish("/odom", {"n": 2})
            for _ in range(100):
                if len(got) == 2:
                    break
                await asyncio.sleep(0.02)
    assert got == [{"n": 1}, {"n": 2}]


async def test_a_one_shot_client_fails_its_call_on_a_binary_garbage_frame():
    with HostileEndpoint(topics=frames(b"\x00\xff\xfe garbage")) as hostile:
        async with RosbridgeClient(hostile.url, call_timeout=5) as client:
            with pytest.raises(NotRosbridgeError, match="not a rosbridge server"):
                await client.call_service("/rosapi/topics")


async def test_a_one_shot_client_refuses_a_frame_above_the_limit_and_names_the_setting():
    with HostileEndpoint(get_param=answer({"value": "x" * 200_000})) as hostile:
        async with RosbridgeClient(hostile.url, max_frame_bytes=100_000) as client:
            with pytest.raises(
                FrameTooLarge, match=r"larger than the 0.0954 MB limit \(FLEET_ROBOT_MAX_FRAME_MB\)"
            ):
                await client.call_service("/rosapi/get_param", {"name": "/robot_description"})


@pytest.mark.parametrize(
    "bad",
    [b"\x00\xff binary", "<html>not rosbridge</html>", "[" * 50_000, "x" * 200_000],
    ids=["binary", "html", "nested-too-deep", "oversize"],
)
async def test_a_link_reconnects_after_a_garbage_or_oversize_frame_and_renews_its_subscription(bad):
    events, got = [], asyncio.Queue()
    with HostileEndpoint() as hostile:
        client = RosbridgeClient(hostile.url, ping_interval=1.0, max_backoff=0.2, max_frame_bytes=100_000)
        client.on_link(lambda up, reason: events.append((up, reason)))
        await client.start()
        try:
            assert await client.wait_connected(3)
            await client.subscribe("/odom", "nav_msgs/Odometry", got.put_nowait)
            hostile.send(bad)
            for _ in range(150):  # down, then up again on a new connection
                if hostile.connections >= 2 and client.is_connected:
                    break
                await asyncio.sleep(0.02)
            assert [up for up, _ in events] == [True, False, True]
            for _ in range(150):  # the subscription is renewed on the new connection
                hostile.publish("/odom", {"n": 1})
                try:
                    assert await next_message(got, 0.1) == {"n": 1}
                    break
                except TimeoutError:
                    continue
            else:
                raise AssertionError("no message after the reconnection")
        finally:
            await client.close()
    reason = events[1][1]
    assert "not rosbridge" in reason or "FLEET_ROBOT_MAX_FRAME_MB" in reason
