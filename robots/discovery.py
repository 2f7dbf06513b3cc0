"""Read one rosbridge endpoint's ROS graph through rosapi and split it into robots (no Django).

Calls (protocol §4): /rosapi/topics (names and types), /rosapi/nodes then /rosapi/node_details per node
(publishers and subscribers come from these: one call per node, not two per topic), /rosapi/services then
/rosapi/service_type per service, /rosapi/action_servers, /rosapi/get_param_names, and /rosapi/get_param
only for the params registration uses (robot_description, velocity limits, initial pose). The per-item
calls run through asyncio.gather under a semaphore, so 1,200 topics cost a few dozen round-trip times.

Robots on one endpoint (see `namespaces`): a first-level namespace is a robot when it holds a
robot_description param (`/robot1/robot_description`, ROS 2 `/robot1/robot_state_publisher:robot_description`)
or at least two nodes and a velocity topic somebody subscribes to. Each such namespace is one robot named
after it ("robot1"); root-level topics of a namespaced endpoint are shared and appear in every robot's graph.
An endpoint without namespaces is one robot, named after the URDF's `<robot name=...>` if there is one,
else by registration after its model (`turtlebot3_burger`, then `turtlebot3_burger_2`, ...).

Infrastructure is never a robot nor a robot's topic (protocol §7): rosapi, rosbridge_websocket, rosout,
/client_count, /connected_clients, /parameter_events, /gazebo/*, */get_loggers, */set_logger_level and the
ROS 2 per-node parameter services. The `/gazebo` node itself stays: its plugins publish robot topics.

Robots are untrusted input: every rosapi reply is checked against REPLIES (lists of names, text, numbers) and
against the caps of robots.limits (names per list, param size) before anything is built from it; a reply that
does not fit refuses the endpoint with a BadReply naming the service, the field and the cap's setting.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
from dataclasses import dataclass, field

from fleetcore.bindings import norm_type
from robots import limits, urdf
from robots.rosbridge import RosbridgeClient, RosbridgeError, RosbridgeTimeout, ServiceError
from robots.rosbridge.codec import preview

INFRA_TOPICS = {"/rosout", "/rosout_agg", "/client_count", "/connected_clients", "/parameter_events"}
INFRA_PREFIXES = ("/rosapi", "/rosbridge_websocket", "/gazebo/", "/rosout/")
INFRA_NODES = {"/rosapi", "/rosapi_params", "/rosbridge_websocket", "/rosout", "/gazebo_gui"}
INFRA_SERVICE_SUFFIXES = (
    "/get_loggers",
    "/set_logger_level",
    "/describe_parameters",
    "/get_parameter_types",
    "/get_parameters",
    "/list_parameters",
    "/set_parameters",
    "/set_parameters_atomically",
)
INFRA_PARAMS = {"/rosdistro", "/rosversion", "/run_id"}
WANTED_PARAMS = re.compile(r"robot_description$|max_vel|initial_pose|initialpose|/base_local_planner$")
VELOCITY_TYPES = {"geometry_msgs/Twist", "geometry_msgs/TwistStamped"}
ROS1_ACTION_PARTS = ("goal", "cancel", "status", "result", "feedback")


MAX_NAME = 255  # the name and type columns of the graph's tables
CONTROL = re.compile(r"[\x00-\x1f\x7f]")


class BadReply(RosbridgeError):
    """A rosapi reply of the wrong shape or above a cap: the endpoint is refused with this one-line reason."""


def _names(value) -> bool:
    return isinstance(value, list) and all(_name(v) for v in value)


def _name(value) -> bool:
    return isinstance(value, str) and len(value) <= MAX_NAME and not CONTROL.search(value)


def _text(value) -> bool:
    return isinstance(value, str) and "\x00" not in value


def _number(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


# rosapi service -> field -> check; a missing field reads as empty (older rosapi versions omit some).
REPLIES = {
    "/rosapi/topics": {"topics": _names, "types": _names},
    "/rosapi/nodes": {"nodes": _names},
    "/rosapi/services": {"services": _names},
    "/rosapi/get_param_names": {"names": _names},
    "/rosapi/action_servers": {"action_servers": _names},
    "/rosapi/get_ros_version": {"version": _number},
    "/rosapi/node_details": {"publishing": _names, "subscribing": _names, "services": _names},
    "/rosapi/service_type": {"type": _name},
    "/rosapi/topic_type": {"type": _name},
    "/rosapi/get_param": {"value": _text},
}
EXPECTED = {
    _names: f"a list of names (text up to {MAX_NAME} characters)",
    _name: f"a name (text up to {MAX_NAME} characters)",
    _text: "text",
    _number: "an integer",
}


# A rosapi read with no answer in time is asked once more before the endpoint's discovery fails: the reads change
# nothing, and one of an endpoint's 1,000 param reads answered late failed the registration of all its 500 robots
# (bench.cluster at 1,000 robots on a busy machine). A silent endpoint still fails, one call's limit later.
READ_RETRIES = 1


async def rosapi(client: RosbridgeClient, service: str, args: dict | None = None) -> dict:
    """Call a rosapi service (asked again, READ_RETRIES times, when no answer came in time) and check its reply
    against REPLIES and the caps; BadReply says what is wrong."""
    for retries_left in range(READ_RETRIES, -1, -1):
        try:
            reply = await client.call_service(service, args)
            break
        except RosbridgeTimeout:
            if not retries_left:
                raise
    caps = limits.current()
    for key, valid in REPLIES[service].items():
        if key not in reply:
            continue
        value = reply[key]
        if not valid(value):
            raise BadReply(
                f"{client.url}: {service} answered {key!r} = {preview(value)}, not {EXPECTED[valid]}"
            )
        if isinstance(value, list) and len(value) > caps.topics:
            raise BadReply(
                f"{client.url}: refused: {service} lists {len(value)} {key}, more than the limit of "
                f"{caps.topics} ({limits.TOPICS_SETTING})"
            )
    if len(reply.get("value") or "") > caps.urdf_bytes:
        name = (args or {}).get("name", "a param")
        raise BadReply(
            f"{client.url}: refused: {name} is {limits.megabytes(len(reply['value']))}, more than the "
            f"{limits.megabytes(caps.urdf_bytes)} limit ({limits.URDF_SETTING})"
        )
    return reply


def is_infra(name: str, kind: str = "topic") -> bool:
    """Tell whether a topic, service, node or param name belongs to the ROS/rosbridge infrastructure."""
    if kind == "node":
        return name in INFRA_NODES or name.startswith(("/rosapi", "/rosbridge_websocket"))
    if kind == "param":
        base = name.split(":", 1)[0]
        return name in INFRA_PARAMS or base.startswith(INFRA_PREFIXES)
    if name in INFRA_TOPICS or name.startswith(INFRA_PREFIXES) or name == "/gazebo":
        return True
    return kind == "service" and name.endswith(INFRA_SERVICE_SUFFIXES)


@dataclass
class TopicInfo:
    name: str
    type: str
    publishers: list[str] = field(default_factory=list)
    subscribers: list[str] = field(default_factory=list)


@dataclass
class Graph:
    """The non-infrastructure ROS graph of an endpoint, or of one robot on it."""

    url: str
    ros_version: int = 1
    namespace: str = ""
    name: str = ""
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    nodes: dict[str, dict[str, list[str]]] = field(default_factory=dict)
    services: dict[str, str] = field(default_factory=dict)
    actions: dict[str, str] = field(default_factory=dict)
    params: dict[str, str | None] = field(default_factory=dict)  # name -> JSON text (None: not read)
    urdf: urdf.URDFFacts | None = None
    urdf_error: str = ""
    start_pose: list[float] | None = None
    start_pose_source: str = ""

    def relative(self, name: str) -> str:
        """Name without this robot's namespace ("/robot1/cmd_vel" -> "cmd_vel")."""
        ns = self.namespace
        return name[len(ns) + 1 :] if ns and name.startswith(ns + "/") else name.lstrip("/")


async def discover(url: str, client: RosbridgeClient | None = None, concurrency: int = 64) -> list[Graph]:
    """Discover one endpoint and return one Graph per robot; RosbridgeError with a one-line reason."""
    own = client is None
    client = client or RosbridgeClient(url)
    try:
        if own:
            await client.connect()
        sem = asyncio.Semaphore(concurrency)
        whole = await read_graph(client, url, sem)
        robots = split(whole)
        await asyncio.gather(*(read_robot_facts(client, g, sem) for g in robots))
        return robots
    finally:
        if own:
            await client.close()


async def read_graph(client: RosbridgeClient, url: str, sem: asyncio.Semaphore) -> Graph:
    """Read topics, nodes with details, services with types, actions and param names."""
    try:
        topics = await rosapi(client, "/rosapi/topics")
    except ServiceError as exc:
        raise RosbridgeError(f"{url}: rosapi does not answer /rosapi/topics ({exc})") from None
    except RosbridgeError as exc:
        if "no answer" in str(exc):
            raise type(exc)(f"{exc} (is rosapi running?)") from None
        raise
    graph = Graph(url=url)
    _topics(graph, topics)
    nodes, services, names, actions, version = await asyncio.gather(
        _optional(client, "/rosapi/nodes", "nodes"),
        _optional(client, "/rosapi/services", "services"),
        _optional(client, "/rosapi/get_param_names", "names"),
        _optional(client, "/rosapi/action_servers", "action_servers"),
        _optional(client, "/rosapi/get_ros_version", "version", default=None),
    )
    graph.ros_version = _ros_version(version, graph)
    await asyncio.gather(_nodes(client, graph, nodes, sem), _services(client, graph, services, sem))
    graph.params = {n: None for n in names if not is_infra(n, "param")}
    await _actions(client, graph, actions, sem)
    return graph


async def _optional(client: RosbridgeClient, service: str, key: str, default=()):
    """Call a rosapi list service; a missing service (older rosapi) gives the default."""
    try:
        return (await rosapi(client, service)).get(key, default)
    except ServiceError:
        return default


async def _bounded(sem: asyncio.Semaphore, coro):
    async with sem:
        return await coro


def _topics(graph: Graph, reply: dict) -> None:
    names, types = reply.get("topics"), reply.get("types")
    if names is None or types is None:
        raise BadReply(f"{graph.url}: /rosapi/topics answered without topic and type lists")
    for name, type_ in zip(names, types, strict=False):
        if not is_infra(name):
            graph.topics[name] = TopicInfo(name, type_)


def _ros_version(version, graph: Graph) -> int:
    """ROS 2 if rosapi says so (get_ros_version exists only there) or types are spelled pkg/msg/Type."""
    if isinstance(version, int) and version in (1, 2):
        return version
    return 2 if any("/msg/" in t.type for t in graph.topics.values()) else 1


async def _nodes(client: RosbridgeClient, graph: Graph, nodes, sem: asyncio.Semaphore) -> None:
    names = [n for n in nodes if not is_infra(n, "node")]
    details = await asyncio.gather(
        *(_bounded(sem, rosapi(client, "/rosapi/node_details", {"node": n})) for n in names),
        return_exceptions=True,
    )
    for name, detail in zip(names, details, strict=True):
        if isinstance(detail, ServiceError):
            detail = {}
        elif isinstance(detail, BaseException):
            raise detail
        entry = {k: list(detail.get(k, [])) for k in ("publishing", "subscribing", "services")}
        graph.nodes[name] = entry
        for key, side in (("publishing", "publishers"), ("subscribing", "subscribers")):
            for topic in entry[key]:
                info = graph.topics.get(topic)
                if info is not None:
                    getattr(info, side).append(name)


def _planner_reconfigure(name: str, ros_version: int) -> bool:
    """A ROS 1 move_base plugin's dynamic_reconfigure service (`.../move_base/<Plugin>/set_parameters`): not
    infrastructure, it is how a local planner takes its top speed (the speed_limit binding)."""
    parts = name.rsplit("/", 3)
    return ros_version == 1 and len(parts) == 4 and parts[1] == "move_base" and parts[3] == "set_parameters"


async def _services(client: RosbridgeClient, graph: Graph, services, sem: asyncio.Semaphore) -> None:
    names = [s for s in services if not is_infra(s, "service") or _planner_reconfigure(s, graph.ros_version)]
    replies = await asyncio.gather(
        *(_bounded(sem, rosapi(client, "/rosapi/service_type", {"service": s})) for s in names),
        return_exceptions=True,
    )
    for name, reply in zip(names, replies, strict=True):
        if isinstance(reply, BaseException) and not isinstance(reply, ServiceError):
            raise reply
        graph.services[name] = reply.get("type", "") if isinstance(reply, dict) else ""


async def _actions(client: RosbridgeClient, graph: Graph, servers, sem: asyncio.Semaphore) -> None:
    """Action servers with their types: ROS 1 from the goal topic, ROS 2 from the hidden feedback topic."""
    found = set(servers)
    if graph.ros_version == 1:
        found |= {
            t.rsplit("/", 1)[0]
            for t in graph.topics
            if t.endswith("/goal") and all(f"{t[:-5]}/{p}" in graph.topics for p in ROS1_ACTION_PARTS)
        }
        for name in sorted(found):
            goal = graph.topics.get(f"{name}/goal")
            graph.actions[name] = (
                goal.type.removesuffix("Goal") if goal and goal.type.endswith("ActionGoal") else ""
            )
        return
    names = sorted(found)
    replies = await asyncio.gather(
        *(
            _bounded(sem, rosapi(client, "/rosapi/topic_type", {"topic": f"{n}/_action/feedback"}))
            for n in names
        ),
        return_exceptions=True,
    )
    for name, reply in zip(names, replies, strict=True):
        if isinstance(reply, BadReply):
            raise reply
        type_ = reply.get("type", "") if isinstance(reply, dict) else ""
        graph.actions[name] = type_.removesuffix("_FeedbackMessage")


def namespaces(graph: Graph) -> list[str]:
    """First-level namespaces that are robots (see the module docstring)."""
    found = set()
    for name in graph.params:
        node = name.split(":", 1)[0] if ":" in name else name.rsplit("/", 1)[0]
        if (
            name.endswith("robot_description")
            and node.count("/") >= (2 if ":" in name else 1)
            and node != "/"
        ):
            found.add("/" + node.split("/")[1])
    per_ns: dict[str, int] = {}
    for node in graph.nodes:
        if node.count("/") >= 2:
            per_ns[_first(node)] = per_ns.get(_first(node), 0) + 1
    for info in graph.topics.values():
        ns = _first(info.name)
        deep = info.name.count("/") >= 2 and per_ns.get(ns, 0) >= 2
        if deep and info.subscribers and norm_type(info.type) in VELOCITY_TYPES:
            found.add(ns)
    return sorted(found)


def _first(name: str) -> str:
    return "/" + name.split("/")[1]


def split(graph: Graph) -> list[Graph]:
    """One Graph per robot: per namespace, or the whole endpoint as one robot.

    A robot's graph has the names under its namespace, and (topics, services, actions) the top-level names of
    no robot's namespace, which all robots share (/clock, /tf). Each name is looked at once, so an endpoint of
    1,000 robots costs as much per robot as one of ten (filtering every name for every robot took 20 s there)."""
    spaces = namespaces(graph)
    if not spaces:
        return [_subgraph(graph, "", {kind: dict(getattr(graph, kind)) for kind in _KINDS})]
    cut = {kind: _by_namespace(getattr(graph, kind), spaces, kind in _SHARED) for kind in _KINDS}
    return [_subgraph(graph, ns, {kind: cut[kind][ns] for kind in _KINDS}) for ns in spaces]


_KINDS = ("topics", "nodes", "services", "actions", "params")
_SHARED = ("topics", "services", "actions")  # a top-level name of these belongs to every robot


def _by_namespace(names: dict, spaces: list[str], shared: bool) -> dict[str, dict]:
    """{namespace: {name: value}} in the names' order: a name under a robot's namespace goes to that robot; with
    `shared`, a top-level name that is no robot's namespace goes to every robot."""
    out: dict[str, dict] = {ns: {} for ns in spaces}
    for name, value in names.items():
        head = _first(name) if name.startswith("/") and "/" in name[1:] else ""
        if head in out:
            out[head][name] = value
        elif shared and name.split(":", 1)[0].count("/") == 1 and _first(name) not in out:
            for part in out.values():
                part[name] = value
    return out


def _subgraph(graph: Graph, ns: str, parts: dict[str, dict]) -> Graph:
    sub = Graph(url=graph.url, ros_version=graph.ros_version, namespace=ns)
    for kind, names in parts.items():
        setattr(sub, kind, names)
    sub.name = ns.strip("/")
    return sub


async def read_robot_facts(client: RosbridgeClient, graph: Graph, sem: asyncio.Semaphore) -> None:
    """Fetch the params registration uses, parse the URDF, name the robot, read its start pose.

    The calls of all the endpoint's robots share one semaphore: an endpoint of 500 robots asked for its 1,000
    params at once answered the last ones after their time limit (each call's limit counts from its sending)."""
    wanted = [n for n in graph.params if WANTED_PARAMS.search(n)]
    values = await asyncio.gather(
        *(_bounded(sem, rosapi(client, "/rosapi/get_param", {"name": n})) for n in wanted),
        return_exceptions=True,
    )
    for name, reply in zip(wanted, values, strict=True):
        if isinstance(reply, dict):
            graph.params[name] = reply.get("value")
        elif not isinstance(reply, ServiceError):  # a param that vanished is skipped; the rest is fatal
            raise reply
    _read_urdf(graph)
    if not graph.name:
        graph.name = graph.urdf.name if graph.urdf and graph.urdf.name else ""  # registration names it
    graph.start_pose, graph.start_pose_source = await start_pose(client, graph)


def _read_urdf(graph: Graph) -> None:
    names = sorted(
        (n for n in graph.params if n.endswith("robot_description")), key=lambda n: "state" not in n
    )
    for name in names:
        text = decode_param(graph.params.get(name))
        try:
            graph.urdf = urdf.parse(text)
            graph.urdf_error = ""
            return
        except urdf.URDFError as exc:
            graph.urdf_error = f"{name}: {exc}"
    if not names:
        graph.urdf_error = "no robot_description param"


def decode_param(text):
    """Decode rosapi's JSON-encoded param value; plain text passes through."""
    if text is None:
        return None
    try:
        return json.loads(text)
    except (TypeError, ValueError):
        return text


async def start_pose(
    client: RosbridgeClient, graph: Graph, wait: float = 0.5
) -> tuple[list[float] | None, str]:
    """Start pose [x, y, yaw]: from params (initial_pose, amcl initial_pose_*), else the latched amcl_pose."""
    from_params = _pose_from_params(graph)
    if from_params:
        return from_params
    topic = next(
        (n for n, t in graph.topics.items() if graph.relative(n) == "amcl_pose" and t.publishers), None
    )
    if topic is None:
        return None, ""
    got: asyncio.Future = asyncio.get_running_loop().create_future()
    sub = await client.subscribe(topic, graph.topics[topic].type, lambda m: got.done() or got.set_result(m))
    try:
        msg = await asyncio.wait_for(got, wait)
    except TimeoutError:
        return None, ""
    finally:
        await client.unsubscribe(sub)
    try:
        return _pose_of(msg["pose"]["pose"]), topic
    except (KeyError, TypeError, ValueError):
        return None, ""


def _pose_from_params(graph: Graph) -> tuple[list[float], str] | None:
    ns = graph.namespace
    value = decode_param(graph.params.get(f"{ns}/initial_pose"))
    if isinstance(value, list) and len(value) >= 3 and all(finite(v) for v in value[:3]):
        return [float(v) for v in value[:3]], f"{ns}/initial_pose"
    for sep, keys in (("/", ("initial_pose_x", "initial_pose_y", "initial_pose_a")),
                      (":", ("initial_pose.x", "initial_pose.y", "initial_pose.yaw"))):  # fmt: skip
        names = [f"{ns}/amcl{sep}{k}" for k in keys]
        vals = [decode_param(graph.params.get(n)) for n in names]
        if all(finite(v) for v in vals):
            return [float(v) for v in vals], names[0].rsplit(sep, 1)[0]
    return None


def _pose_of(pose: dict) -> list[float]:
    """[x, y, yaw] of a geometry_msgs/Pose; ValueError unless every number is finite."""
    p, q = pose["position"], pose["orientation"]
    numbers = [p["x"], p["y"], q["x"], q["y"], q["z"], q["w"]]
    if not all(finite(v) for v in numbers):
        raise ValueError(f"not a pose: {preview(pose)}")
    yaw = math.atan2(2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2))
    return [float(p["x"]), float(p["y"]), round(yaw, 6)]


def finite(value) -> bool:
    """A real number a float holds (JSON allows NaN, Infinity and integers too large for a float)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False
