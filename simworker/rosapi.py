"""rosapi and the rosbridge node's own graph entries, as rosbridge_suite shows them (protocol §4, §7)."""

from __future__ import annotations

import json

from simworker.graph import Graph, ServiceError
from simworker.messages import MsgDef, Registry, base_name, registry

ROSAPI_SERVICES = [
    "topics", "topics_for_type", "topics_and_raw_types", "services", "services_for_type", "nodes",
    "node_details", "action_servers", "topic_type", "service_type", "publishers", "subscribers",
    "service_providers", "service_node", "service_host", "message_details", "service_request_details",
    "service_response_details", "get_param", "set_param", "has_param", "delete_param", "search_param",
    "get_param_names", "get_time",
]  # fmt: skip
SRV_NAMES = {"action_servers": "GetActionServers", "get_ros_version": "GetROSVersion", "get_time": "GetTime"}
ROS2_ONLY, ROS1_ONLY = {"get_ros_version"}, {"service_host", "search_param"}


def _srv_type(name: str, ros_version: int) -> str:
    camel = SRV_NAMES.get(name) or "".join(p.capitalize() for p in name.split("_"))
    return f"rosapi/{camel}" if ros_version == 1 else f"rosapi_msgs/srv/{camel}"


def install(graph: Graph, port: int) -> None:
    """Add /rosout, /rosapi, /rosbridge_websocket and the rosapi services to a fresh graph."""
    v = graph.ros_version
    t = graph.msg_type
    graph.add_publisher("/rosbridge_websocket", "/client_count", t("std_msgs/Int32"))
    graph.add_publisher("/rosbridge_websocket", "/connected_clients", t("rosbridge_msgs/ConnectedClients"))
    graph.latched_topics |= {"/client_count", "/connected_clients"}
    if v == 1:
        graph.add_subscriber("/rosout", "/rosout", "rosgraph_msgs/Log")
        graph.add_publisher("/rosout", "/rosout_agg", "rosgraph_msgs/Log")
        graph.params.update(
            {
                "/rosdistro": "noetic\n",
                "/rosversion": "1.15.15\n",
                "/run_id": "sim-" + str(port),
                "/rosbridge_websocket/port": port,
                "/rosbridge_websocket/address": "0.0.0.0",
            }
        )
    else:
        graph.node("/rosapi_params")
        graph.params.update({"/rosbridge_websocket:port": port, "/rosbridge_websocket:address": ""})
    names = [n for n in ROSAPI_SERVICES if n not in (ROS1_ONLY if v == 2 else ())]
    if v == 2:
        names.append("get_ros_version")
    handlers = _handlers(graph)
    for name in names:
        graph.add_service("/rosapi", f"/rosapi/{name}", _srv_type(name, v), handlers.get(name))
    for node in ("/rosapi", "/rosbridge_websocket"):
        graph.add_publisher(node, "/rosout", t("rosgraph_msgs/Log") if v == 1 else "rcl_interfaces/msg/Log")


def finish(graph: Graph) -> None:
    """Add per-node infrastructure services: ROS 1 loggers, ROS 2 parameter services and /parameter_events."""
    for node in list(graph.nodes):
        if graph.ros_version == 1:
            graph.add_service(node, f"{node}/get_loggers", "roscpp/GetLoggers")
            graph.add_service(node, f"{node}/set_logger_level", "roscpp/SetLoggerLevel")
        else:
            graph.add_publisher(node, "/rosout", "rcl_interfaces/msg/Log")
            graph.add_publisher(node, "/parameter_events", "rcl_interfaces/msg/ParameterEvent")
            for srv in (
                "describe_parameters",
                "get_parameter_types",
                "get_parameters",
                "list_parameters",
                "set_parameters",
                "set_parameters_atomically",
            ):
                camel = "".join(p.capitalize() for p in srv.split("_"))
                graph.add_service(node, f"{node}/{srv}", f"rcl_interfaces/srv/{camel}")


def _hidden(name: str) -> bool:
    return any(tok.startswith("_") for tok in name.split("/"))


def _handlers(g: Graph) -> dict:
    """Return the rosapi service handlers, keyed by short name."""
    v2 = g.ros_version == 2
    types = registry(g.ros_version)

    def topics(_a):
        names = [t for t in g.topics() if not (v2 and _hidden(t))]
        return {"topics": names, "types": [g.topic_types.get(t, "") for t in names]}

    def services(_a):
        return {"services": [s for s in g.services() if not (v2 and _hidden(s))]}

    def node_details(a):
        info = g.nodes.get(_str(a, "node"))
        if info is None:
            return {"subscribing": [], "publishing": [], "services": []}
        return {
            "subscribing": sorted(info.subs),
            "publishing": sorted(info.pubs),
            "services": sorted(info.services),
        }

    def action_servers(_a):
        if v2:
            names = {t.rsplit("/_action/", 1)[0] for t in g.topics() if t.endswith("/_action/status")}
            return {"action_servers": sorted(n for n in names if f"{n}/_action/feedback" in g.topic_types)}
        parts = ("cancel", "feedback", "goal", "result", "status")
        names = {t.rsplit("/", 1)[0] for t in g.topics() if t.endswith("/status")}
        return {"action_servers": sorted(n for n in names if all(f"{n}/{p}" in g.topic_types for p in parts))}

    return {
        "topics": topics,
        "topics_for_type": lambda a: {
            "topics": [t for t in g.topics() if g.topic_types[t] == _str(a, "type")]
        },
        "topics_and_raw_types": lambda a: {
            **topics(a),
            "typedefs_full_text": ["" for _ in topics(a)["topics"]],
        },
        "services": services,
        "services_for_type": lambda a: {
            "services": [s for s in g.services() if g.service_types[s] == _str(a, "type")]
        },
        "nodes": lambda _a: {"nodes": sorted(g.nodes)},
        "node_details": node_details,
        "action_servers": action_servers,
        "topic_type": lambda a: {"type": g.topic_types.get(_str(a, "topic"), "")},
        "service_type": lambda a: {"type": g.service_types.get(_str(a, "service"), "")},
        "publishers": lambda a: {"publishers": g.publishers(_str(a, "topic"))},
        "subscribers": lambda a: {"subscribers": g.subscribers(_str(a, "topic"))},
        "service_providers": lambda a: {
            "providers": sorted(
                n
                for n, i in g.nodes.items()
                if any(g.service_types[s] == _str(a, "service") for s in i.services)
            )
        },
        "service_node": lambda a: {
            "node": next((n for n, i in g.nodes.items() if _str(a, "service") in i.services), "")
        },
        "service_host": lambda _a: {"host": "localhost"},
        "message_details": lambda a: {"typedefs": types.typedefs(types.message(_str(a, "type")))},
        "service_request_details": lambda a: {"typedefs": types.typedefs(_service(types, a)[0])},
        "service_response_details": lambda a: {"typedefs": types.typedefs(_service(types, a)[1])},
        "get_time": lambda _a: {"time": g.stamp()},
        "get_ros_version": lambda _a: {"version": 2, "distro": "humble"},
        **_param_handlers(g),
    }


def _service(types: Registry, args: dict) -> tuple[MsgDef, MsgDef]:
    """The request and response definitions of args' service type; the call fails for an unknown one."""
    name = _str(args, "type")
    parts = types.service(name)
    if parts is None:
        pkg, _, short = base_name(name).partition("/")
        raise ServiceError(
            f"Unable to import srv class {short} from package {pkg}. Caused by No module named '{pkg}'"
        )
    return parts


def _str(args: dict, key: str) -> str:
    value = args.get(key, "")
    if not isinstance(value, str):
        raise ServiceError(f"Expected field {key} to be a string. Invalid value: {value!r}")
    return value


def _param_handlers(g: Graph) -> dict:
    """Return get/set/has/delete/search/get_param_names handlers over the graph's params."""

    def get_value(name: str):
        if name in g.params:
            return g.params[name]
        prefix = name.rstrip("/") + "/"
        sub = {k[len(prefix) :]: v for k, v in g.params.items() if k.startswith(prefix)}
        if not sub or g.ros_version == 2:
            raise KeyError(name)
        tree: dict = {}
        for key, value in sub.items():
            *parents, leaf = key.split("/")
            node = tree
            for p in parents:
                node = node.setdefault(p, {})
            node[leaf] = value
        return tree

    def get_param(a):
        name = _str(a, "name")
        try:
            return {"value": json.dumps(get_value(name))}
        except KeyError:
            default = a.get("default", a.get("default_value", ""))
            if default in ("", None):
                return {"value": "null"}
            try:
                return {"value": json.dumps(json.loads(default))}
            except (TypeError, ValueError):
                return {"value": json.dumps(default)}

    def set_param(a):
        name, text = _str(a, "name"), _str(a, "value")
        try:
            g.params[name] = json.loads(text)
        except ValueError as exc:
            raise ServiceError(f"set_param: value of {name} is not JSON: {exc}") from exc
        return {}

    def has_param(a):
        try:
            get_value(_str(a, "name"))
            return {"exists": True}
        except KeyError:
            return {"exists": False}

    return {
        "get_param": get_param,
        "set_param": set_param,
        "has_param": has_param,
        "delete_param": lambda a: (g.params.pop(_str(a, "name"), None), {})[1],
        "search_param": lambda a: {
            "global_name": next((k for k in g.params if k.endswith("/" + _str(a, "name"))), "")
        },
        "get_param_names": lambda _a: {"names": sorted(g.params)},
    }
