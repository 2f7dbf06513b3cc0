"""Liveness: a link per endpoint; offline when the endpoint goes away, online again after it restarts, pushed live."""

import asyncio

import pytest
from asgiref.sync import sync_to_async
from channels.layers import get_channel_layer

import live
from live import FLEET_GROUP
from robots.links import LinkManager
from robots.models import Robot
from robots.registration import register_endpoints

pytestmark = [pytest.mark.timeout(60), pytest.mark.asyncio, pytest.mark.django_db(transaction=True)]


async def status_of(name: str) -> str:
    return (await Robot.objects.aget(name=name)).link_status


async def wait_status(name: str, status: str, timeout: float = 5.0) -> None:
    for _ in range(int(timeout / 0.05)):
        if await status_of(name) == status:
            return
        await asyncio.sleep(0.05)
    raise AssertionError(f"{name} never became {status}")


async def next_status(layer, channel: str, link_status: str) -> dict:
    """The next pushed robot.status with this link status (state changes push robot.status too)."""
    while True:
        for msg in live.unbatched(await asyncio.wait_for(layer.receive(channel), 5)):  # as every group reader
            if msg.get("type") == "robot.status" and msg["link_status"] == link_status:
                return msg


async def test_offline_then_online_after_the_endpoint_restarts_and_hooks_resubscribe(endpoint):
    ep = endpoint()
    await sync_to_async(register_endpoints)([ep.url])
    layer = get_channel_layer()
    channel = await layer.new_channel()
    await layer.group_add(FLEET_GROUP, channel)
    seen = asyncio.Queue()

    async def odom_hook(client, robots):
        (robot,) = robots
        topic, type_ = robot["bindings"]["odometry"]
        await client.subscribe(topic, type_, seen.put_nowait)

    manager = LinkManager([ep.url], hooks=[odom_hook])
    task = asyncio.create_task(manager.run())
    try:
        await asyncio.sleep(0.3)
        ep.stop()
        await wait_status("fakebot", Robot.Link.OFFLINE)
        assert (await next_status(layer, channel, "offline"))["robot"] == "fakebot"
        ep.start()
        await wait_status("fakebot", Robot.Link.ONLINE)
        pushed = await next_status(layer, channel, "online")
        assert pushed["robot"] == "fakebot"
        for _ in range(100):  # the state machine follows the link: offline -> ready
            if (await Robot.objects.aget(name="fakebot")).state == Robot.State.READY:
                break
            await asyncio.sleep(0.05)
        assert (await Robot.objects.aget(name="fakebot")).state == Robot.State.READY
        assert pushed["last_seen"] is not None
        ep.thread.call(ep.server.publish, "/odom", {"pose": {"pose": {"position": {"x": 1.5}}}})
        msg = await asyncio.wait_for(seen.get(), 5)  # the hook's subscription was renewed after the restart
        assert msg["pose"]["pose"]["position"]["x"] == 1.5
    finally:
        manager.stop()
        await asyncio.wait_for(task, 10)
        await layer.group_discard(FLEET_GROUP, channel)


async def test_an_endpoint_that_is_down_from_the_start_is_offline(endpoint):
    ep = endpoint()
    await sync_to_async(register_endpoints)([ep.url])
    ep.stop()
    manager = LinkManager([ep.url])
    task = asyncio.create_task(manager.run())
    try:
        await wait_status("fakebot", Robot.Link.OFFLINE)
    finally:
        manager.stop()
        await asyncio.wait_for(task, 10)


ODOMETRY_AT_1_5 = {
    "header": {"seq": 0, "stamp": {"secs": 1, "nsecs": 0}, "frame_id": "odom"},
    "child_frame_id": "base_link",
    "pose": {
        "pose": {"position": {"x": 1.5, "y": 0.0, "z": 0.0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}
    },
    "twist": {"twist": {"linear": {"x": 0.0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0.0}}},
}


async def test_links_stream_map_poses_to_the_portal(endpoint):
    """The links process's pose hook: odometry on the robot's bound topic becomes a batched map pose."""
    from robots.poses import PoseHub, link_hook

    ep = endpoint()
    await sync_to_async(register_endpoints)([ep.url])
    robot = await Robot.objects.aget(name="fakebot")
    batches = asyncio.Queue()

    async def sink(batch):
        batches.put_nowait(batch)

    hub = PoseHub(publish=sink, rate_hz=20)
    manager = LinkManager([ep.url], hooks=[link_hook(hub)])
    tasks = [asyncio.create_task(manager.run()), asyncio.create_task(hub.run(manager.stopping))]
    try:
        for _ in range(100):
            ep.thread.call(ep.server.publish, "/odom", ODOMETRY_AT_1_5)
            try:
                batch = await asyncio.wait_for(batches.get(), 0.2)
            except TimeoutError:
                continue
            (pose,) = batch
            assert pose["id"] == robot.pk
            assert pose["x"] == pytest.approx(robot.start_pose[0] + 1.5 if robot.start_pose else 1.5)
            break
        else:
            raise AssertionError("no pose batch reached the portal")
    finally:
        manager.stop()
        await asyncio.wait_for(asyncio.gather(*tasks), 10)


async def test_the_pose_hook_subscribes_every_robot_while_djangos_shared_sync_thread_is_busy(endpoint):
    """The links process writes each endpoint's link status through Django's one shared sync thread, a push per
    robot; at 1,000 robots the pose hook, which made each robot's subscriptions on that thread behind those
    writes, had subscribed 2 robots when the bench's dashboards looked (bench.cluster). It no longer waits."""
    import threading

    from robots.poses import PoseHub, link_hook

    ep = endpoint()
    await sync_to_async(register_endpoints)([ep.url])
    robot = await Robot.objects.aget(name="fakebot")
    odometry = (await robot.bindings.aget(action="odometry")).target

    class Link:  # what the hook uses of a RosbridgeClient
        url, closed, subscribed = ep.url, True, []

        async def subscribe(self, topic, type_, callback, throttle_rate=0, queue_length=0):
            self.subscribed.append(topic)

    release = threading.Event()
    shared = asyncio.ensure_future(sync_to_async(release.wait)(10))  # the shared thread, held by a long write
    try:
        await asyncio.wait_for(link_hook(PoseHub(publish=None))(Link(), []), 5)
        assert odometry in Link.subscribed and not shared.done()
    finally:
        release.set()
        await shared


async def test_a_newly_registered_endpoint_is_linked_while_djangos_shared_sync_thread_is_busy(endpoint):
    """The link status writes (a save, an alert and a push per robot) queue on Django's shared sync thread; the
    links process's look for new endpoints waited behind them, and in one 1,000-robot run the second shard was
    never linked while they ran (bench.cluster). It no longer waits."""
    import threading

    ep = endpoint()
    await sync_to_async(register_endpoints)([ep.url])
    release = threading.Event()
    shared = asyncio.ensure_future(sync_to_async(release.wait)(10))  # the shared thread, held by a long write
    manager = LinkManager()  # the endpoints as registered
    task = asyncio.create_task(manager.run())
    try:
        for _ in range(100):
            if ep.url in manager.links and manager.links[ep.url].is_connected:
                break
            await asyncio.sleep(0.05)
        assert manager.links[ep.url].is_connected and not shared.done()
    finally:
        release.set()
        await shared
        manager.stop()
        await asyncio.wait_for(task, 10)


async def test_a_link_outlives_bad_frames_and_reconnects_after_garbage():
    """A publish with a list for a topic is dropped; a garbage frame takes the link down and it comes back."""
    from tests.robots.fakes import HostileEndpoint

    with HostileEndpoint() as hostile:
        (result,) = await sync_to_async(register_endpoints)([hostile.url])
        assert result.ok
        seen = asyncio.Queue()

        async def odom_hook(client, robots):
            (robot,) = robots
            await client.subscribe(*robot["bindings"]["odometry"], seen.put_nowait)

        manager = LinkManager([hostile.url], hooks=[odom_hook])
        task = asyncio.create_task(manager.run())
        try:
            for _ in range(100):  # the link is up: the hook's subscription reached the endpoint
                if "/odom" in hostile.subscribed:
                    break
                await asyncio.sleep(0.05)
            linked = hostile.connections  # registration's connection, and the link's
            hostile.send('{"op": "publish", "topic": ["x"], "msg": {}}')
            hostile.publish("/odom", {"n": 1})
            assert await asyncio.wait_for(seen.get(), 5) == {"n": 1}
            assert hostile.connections == linked  # a bad frame is dropped, the link stays as it was
            hostile.send(b"\x00\xff not rosbridge")
            for _ in range(200):
                if hostile.connections == linked + 1 and (await status_of("hostile")) == Robot.Link.ONLINE:
                    break
                await asyncio.sleep(0.05)
            assert hostile.connections == linked + 1
            for _ in range(100):  # the subscription is renewed on the new connection
                hostile.publish("/odom", {"n": 2})
                try:
                    assert await asyncio.wait_for(seen.get(), 0.1) == {"n": 2}
                    break
                except TimeoutError:
                    continue
            else:
                raise AssertionError("no odometry after the reconnection")
        finally:
            manager.stop()
            await asyncio.wait_for(task, 10)


async def test_battery_messages_reach_the_database_only_when_a_robots_charge_changes_class(monkeypatch):
    """100 robots' batteries every 10 s were 10 transactions a second per 100 robots; only a change of class
    (the first message, low, ok again) needs one."""
    from robots import links

    checked = []
    monkeypatch.setattr(links, "check_battery", lambda robot_id, message: checked.append((robot_id, message)))

    class Client:
        callbacks = {}

        async def subscribe(self, topic, type_, callback, throttle_rate=0):
            self.callbacks[topic] = callback

    client = Client()
    robots = [
        {"id": pk, "bindings": {"battery": (f"/r{pk}/battery", "sensor_msgs/BatteryState")}} for pk in (1, 2)
    ]
    await links.battery_hook(client, robots)
    one, two = client.callbacks["/r1/battery"], client.callbacks["/r2/battery"]
    for charge in (0.9, 0.8, 0.7, 0.25, 0.1, 0.12, 0.9, float("nan")):
        one({"percentage": charge})
    two({"percentage": 50})
    await asyncio.gather(*links._BATTERY_CHECKS)
    # (the checks run in threads: their order is not the messages')
    assert sorted((pk, m["percentage"]) for pk, m in checked) == [(1, 0.1), (1, 0.9), (1, 0.9), (2, 50)]


async def test_the_stop_targets_are_rebuilt_when_a_robot_or_binding_changes_not_when_a_state_does():
    await sync_to_async(_stop_targets_follow_their_rows)()


def _stop_targets_follow_their_rows() -> None:
    from robots.links import stop_targets, targets_mark
    from robots.models import Binding

    url = "ws://127.0.0.1:9091"
    turtlebot = Robot.objects.create(name="turtlebot", model="turtlebot3_burger", endpoint=url)
    move = Binding.objects.create(
        robot=turtlebot, action="move", target="/cmd_vel", message_type="geometry_msgs/Twist", how="exact"
    )
    mark = targets_mark([url])
    assert stop_targets([url])["turtlebot"].move_topic == "/cmd_vel"
    # a state, a hold, last_seen: written with .update(), read by no command surface
    Robot.objects.filter(pk=turtlebot.pk).update(state=Robot.State.MOTION, held_reason="a test's stop")
    assert targets_mark([url]) == mark

    move.target = "/renamed/cmd_vel"
    move.save()
    assert targets_mark([url]) != mark
    assert stop_targets([url])["turtlebot"].move_topic == "/renamed/cmd_vel"

    mark = targets_mark([url])
    Robot.objects.create(name="husky", model="husky", endpoint=url, namespace="husky")
    assert targets_mark([url]) != mark
    mark = targets_mark([url])
    turtlebot.delete()
    assert targets_mark([url]) != mark and "turtlebot" not in stop_targets([url])
