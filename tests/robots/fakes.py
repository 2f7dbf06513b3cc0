"""Endpoints for the registration tests: a graph-only rosbridge server, servers that are not rosbridge, and a
hostile one (HostileEndpoint) whose every rosapi reply and frame a test chooses.

GraphEndpoint serves a hand-built ROS graph through simworker's rosbridge server and rosapi (so the wire
behaviour is the simulator's, which follows rosbridge_suite), without physics; tests mutate its graph,
stop and restart it on the same port.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import threading
import time

from websockets.asyncio.server import serve

from simworker import rosapi
from simworker.graph import Graph
from simworker.server import RosbridgeServer
from simworker.testing import free_port


class LoopThread:
    """An event loop in a daemon thread, for servers the tests start and stop."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    def run(self, coro, timeout: float = 10.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def call(self, fn, *args):
        future: concurrent.futures.Future = concurrent.futures.Future()

        def run():
            try:
                future.set_result(fn(*args))
            except BaseException as exc:
                future.set_exception(exc)

        self.loop.call_soon_threadsafe(run)
        return future.result(5)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        if not self.thread.is_alive():
            self.loop.close()  # not left to the collector, which would close it under another test's loop


def robot_graph(graph: Graph, ns: str = "", name: str = "fakebot", wheels: int = 2) -> None:
    """Add a small differential robot (TurtleBot3-like) under a namespace."""
    t = graph.msg_type
    graph.add_subscriber(f"{ns}/base_driver", f"{ns}/cmd_vel", t("geometry_msgs/Twist"))
    graph.add_publisher(f"{ns}/base_driver", f"{ns}/odom", t("nav_msgs/Odometry"))
    graph.add_publisher(f"{ns}/laser", f"{ns}/scan", t("sensor_msgs/LaserScan"))
    joints = "".join(
        f'<joint name="wheel_{i}_joint" type="continuous"><parent link="base_link"/><child link="wheel_{i}_link"/></joint>'
        for i in range(wheels)
    )
    urdf = f'<robot name="{name}"><link name="base_link"/>{joints}</robot>'
    key = (
        f"{ns}/robot_description"
        if graph.ros_version == 1
        else f"{ns}/robot_state_publisher:robot_description"
    )
    graph.params[key] = urdf
    if graph.ros_version == 2:
        graph.node(f"{ns}/robot_state_publisher")


def big_graph(graph: Graph, topics: int = 1200) -> None:
    """One robot with `topics` topics spread over 100 nodes, plus its cmd_vel and odom."""
    robot_graph(graph, "", "bigbot")
    for i in range(topics - 3):
        node = f"/sensor_node_{i % 100}"
        graph.add_publisher(node, f"/sensors/group_{i % 40}/reading_{i}", "std_msgs/Float32")


class GraphEndpoint:
    """A rosbridge server for a Graph on a fixed port, in its own thread; restartable."""

    def __init__(self, ros_version: int = 1, build=robot_graph, port: int | None = None) -> None:
        self.graph = Graph(ros_version, time.time)
        build(self.graph)
        self.port = port or free_port()
        self.server = RosbridgeServer("fake", self.graph, self.port)  # installs rosapi
        rosapi.finish(self.graph)
        self.thread = LoopThread()

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def start(self) -> GraphEndpoint:
        """Listen (again) on the same port."""
        self.thread.run(self.server.start("127.0.0.1"))
        return self

    def stop(self) -> None:
        """Stop listening and drop every client, as a restarting rosbridge does."""
        self.thread.run(self.server.stop())

    def mutate(self, fn) -> None:
        """Run fn(graph) on the server's loop."""
        self.thread.call(fn, self.graph)

    def close(self) -> None:
        self.stop()
        self.thread.close()

    def __enter__(self) -> GraphEndpoint:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


class OddServer:
    """A WebSocket server that is not rosbridge: `garbage` answers nonsense, `silent` never answers."""

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.port = free_port()
        self.thread = LoopThread()
        self._server = None

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    async def _handle(self, ws) -> None:
        with contextlib.suppress(Exception):
            async for _raw in ws:
                if self.mode == "garbage":
                    await ws.send("<html>hello, I am not rosbridge</html>")

    async def _start(self) -> None:
        self._server = await serve(self._handle, "127.0.0.1", self.port)

    async def _stop(self) -> None:
        self._server.close()
        await self._server.wait_closed()

    def __enter__(self) -> OddServer:
        self.thread.run(self._start())
        return self

    def __exit__(self, *exc) -> None:
        self.thread.run(self._stop())
        self.thread.close()


class HttpServer:
    """A plain HTTP server (e.g. someone's web app on the port): answers 200 and no WebSocket upgrade."""

    def __init__(self) -> None:
        self.port = free_port()
        self.thread = LoopThread()

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    async def _handle(self, reader, writer) -> None:
        await reader.readuntil(b"\r\n\r\n")
        writer.write(b"HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: 5\r\n\r\nhello")
        await writer.drain()
        writer.close()

    def __enter__(self) -> HttpServer:
        async def start():
            self._server = await asyncio.start_server(self._handle, "127.0.0.1", self.port)

        self.thread.run(start())
        return self

    def __exit__(self, *exc) -> None:
        async def stop():
            self._server.close()

        self.thread.run(stop())
        self.thread.close()


# ----- a hostile endpoint -----
HOSTILE_URDF = '<robot name="{name}"><link name="base_link"/>{joints}{padding}</robot>'
WHEELS = "".join(
    f'<joint name="wheel_{i}_joint" type="continuous"><parent link="base_link"/><child link="wheel_{i}"/></joint>'
    for i in range(2)
)


def hostile_urdf(name: str = "hostile", size: int = 0) -> str:
    """A two-wheeled robot's URDF, padded with an XML comment to about `size` characters."""
    padding = f"<!--{'x' * size}-->" if size else ""
    return HOSTILE_URDF.format(name=name, joints=WHEELS, padding=padding)


def answer(values: dict, result: bool = True):
    """A reply: the well-formed service_response with these values."""

    def frames(call: dict) -> list:
        return [json.dumps({"op": "service_response", "id": call["id"], "service": call["service"],
                            "values": values, "result": result})]  # fmt: skip

    return frames


def frames(*raw):
    """A reply: these frames as they are (text or bytes), whatever was asked."""
    return lambda call: list(raw)


def with_id(make):
    """A reply built from the call's id: make(id) gives one frame as a dict, sent as JSON."""
    return lambda call: [json.dumps(make(call["id"]))]


def fragmented(values: dict, parts: int = 3, total=None):
    """A reply: the service_response cut into `fragment` ops with the call's id (total as given, if given)."""

    def make(call: dict) -> list:
        text = answer(values)(call)[0]
        size = -(-len(text) // parts)
        chunks = [text[i : i + size] for i in range(0, len(text), size)]
        count = len(chunks) if total is None else total
        return [json.dumps({"op": "fragment", "id": call["id"], "data": chunk, "num": n, "total": count})
                for n, chunk in enumerate(chunks)]  # fmt: skip

    return make


def robot_replies(name: str = "hostile", urdf: str | None = None, topics: int = 0) -> dict:
    """What rosapi answers for one small ROS 1 robot (cmd_vel, odom, a URDF), plus `topics` extra topics."""
    extra = [f"/extra_{i}" for i in range(topics)]
    types = ["geometry_msgs/Twist", "nav_msgs/Odometry"] + ["std_msgs/Bool"] * topics
    return {
        "/rosapi/topics": answer({"topics": ["/cmd_vel", "/odom", *extra], "types": types}),
        "/rosapi/nodes": answer({"nodes": ["/base"]}),
        "/rosapi/node_details": answer(
            {"publishing": ["/odom"], "subscribing": ["/cmd_vel"], "services": []}
        ),
        "/rosapi/services": answer({"services": []}),
        "/rosapi/get_param_names": answer({"names": ["/robot_description"]}),
        "/rosapi/get_param": answer({"value": json.dumps(urdf if urdf is not None else hostile_urdf(name))}),
        "/rosapi/action_servers": answer({"action_servers": []}),
    }


class HostileEndpoint:
    """A rosbridge endpoint that lies: rosapi answers from `replies`, and any frame is sent on demand.

    A reply is a function of the call message giving the frames to send (see answer, frames, with_id,
    fragmented); the defaults describe one small robot (robot_replies), so a test overrides only the reply it
    is about. Services not in the table fail as rosbridge says ("Service ... does not exist"). send() pushes a
    frame to every client; subscriptions are recorded, so publish() reaches the topics clients asked for.
    """

    def __init__(
        self, name: str = "hostile", urdf: str | None = None, extra_topics: int = 0, **replies
    ) -> None:
        self.replies = {
            **robot_replies(name, urdf, extra_topics),
            **{_service(k): v for k, v in replies.items()},
        }
        self.port = free_port()
        self.thread = LoopThread()
        self.clients: set = set()
        self.connections = 0
        self.subscribed: set[str] = set()
        self._server = None

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    async def _handle(self, ws) -> None:
        self.clients.add(ws)
        self.connections += 1
        try:
            async for raw in ws:
                await self._on(ws, json.loads(raw))
        except Exception:
            pass  # a client that went away mid-send
        finally:
            self.clients.discard(ws)

    async def _on(self, ws, message: dict) -> None:
        if message.get("op") == "subscribe":
            self.subscribed.add(message["topic"])
        if message.get("op") != "call_service":
            return
        missing = answer(f"Service {message['service']} does not exist", result=False)
        for frame in self.replies.get(message["service"], missing)(message):
            await ws.send(frame)

    def send(self, frame) -> None:
        """Send one frame (text or bytes) to every connected client."""

        async def send_all():
            for ws in list(self.clients):
                with contextlib.suppress(Exception):
                    await ws.send(frame)

        self.thread.run(send_all())

    def publish(self, topic: str, msg: dict) -> None:
        self.send(json.dumps({"op": "publish", "topic": topic, "msg": msg}))

    def __enter__(self) -> HostileEndpoint:
        async def start():
            self._server = await serve(self._handle, "127.0.0.1", self.port, max_size=None, compression=None)

        self.thread.run(start())
        return self

    def __exit__(self, *exc) -> None:
        async def stop():
            self._server.close()
            await self._server.wait_closed()

        self.thread.run(stop())
        self.thread.close()


def _service(key: str) -> str:
    """Keyword arguments name rosapi services without the prefix: nodes= is /rosapi/nodes."""
    return key if key.startswith("/") else f"/rosapi/{key}"


def nav2_robot(graph: Graph, ns: str, name: str, cmd_vel: str = "cmd_vel", odom: str = "odom") -> None:
    """A ROS 2 robot of another maker with nav2 humble as its bringup shows it: the base driver, the navigation
    actions (hidden /_action/ topics and services), /goal_pose, the controller's speed_limit, the velocity
    smoother feeding the base, /diagnostics and /battery_state. Names relative to the robot's namespace."""
    graph.add_subscriber(f"{ns}/base_driver", f"{ns}/{cmd_vel}", "geometry_msgs/msg/Twist")
    graph.add_publisher(f"{ns}/base_driver", f"{ns}/{odom}", "nav_msgs/msg/Odometry")
    graph.add_publisher(f"{ns}/base_driver", f"{ns}/battery_state", "sensor_msgs/msg/BatteryState")
    graph.add_publisher(f"{ns}/base_driver", "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
    graph.add_publisher(f"{ns}/lidar", f"{ns}/scan", "sensor_msgs/msg/LaserScan")
    bt = f"{ns}/bt_navigator"
    for action, kind in (
        ("navigate_to_pose", "NavigateToPose"),
        ("navigate_through_poses", "NavigateThroughPoses"),
    ):
        act, type_ = f"{ns}/{action}/_action", f"nav2_msgs/action/{kind}"
        graph.add_publisher(bt, f"{act}/feedback", f"{type_}_FeedbackMessage")
        graph.add_publisher(bt, f"{act}/status", "action_msgs/msg/GoalStatusArray")
        graph.add_service(bt, f"{act}/send_goal", f"{type_}_SendGoal")
        graph.add_service(bt, f"{act}/cancel_goal", "action_msgs/srv/CancelGoal")
        graph.add_service(bt, f"{act}/get_result", f"{type_}_GetResult")
    graph.add_subscriber(bt, f"{ns}/goal_pose", "geometry_msgs/msg/PoseStamped")
    graph.add_subscriber(f"{ns}/controller_server", f"{ns}/{odom}", "nav_msgs/msg/Odometry")
    graph.add_subscriber(f"{ns}/controller_server", f"{ns}/speed_limit", "nav2_msgs/msg/SpeedLimit")
    graph.add_publisher(f"{ns}/controller_server", f"{ns}/cmd_vel_nav", "geometry_msgs/msg/Twist")
    graph.add_subscriber(f"{ns}/velocity_smoother", f"{ns}/cmd_vel_nav", "geometry_msgs/msg/Twist")
    graph.add_publisher(f"{ns}/velocity_smoother", f"{ns}/{cmd_vel}", "geometry_msgs/msg/Twist")
    graph.add_publisher(
        f"{ns}/lifecycle_manager_navigation", "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"
    )
    urdf = f'<robot name="{name}"><link name="base_link"/></robot>'
    graph.params[f"{ns}/robot_state_publisher:robot_description"] = urdf
    graph.node(f"{ns}/robot_state_publisher")
