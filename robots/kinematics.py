"""A robot's model and velocity limits from its graph (no Django).

Limits come from the base controller's params when the robot exposes them (ROS 1
`<ns>/mobile_base_controller/linear/x/max_velocity`, ROS 2 `<ns>/<controller>:linear.x.max_velocity`), else
from the robot-model catalog's LIMITS (fleetcore/catalog.py), which the simulator's models read too.
"""

from __future__ import annotations

import re

from fleetcore.catalog import DEFAULT_LIMITS, LIMITS, SIGNATURES
from robots.discovery import Graph, decode_param, finite

LINEAR = re.compile(r"linear[./]x[./]max_velocity$")
ANGULAR = re.compile(r"angular[./]z[./]max_velocity$")


def guess_model(graph: Graph) -> str:
    """Name the robot's model from its URDF name, else its node and topic names; "" when unknown."""
    urdf_name = (graph.urdf.name if graph.urdf else "").lower()
    names = " ".join([urdf_name, *graph.nodes, *graph.topics]).lower()
    for key, words in SIGNATURES:
        if any(w in urdf_name for w in words):
            return key
    for key, words in SIGNATURES:
        if any(w in names for w in words):
            return key
    return ""


def limits(graph: Graph, model: str) -> tuple[float, float, str]:
    """(max_linear, max_angular, source): controller params first, else the per-model table."""
    linear = _param(graph, LINEAR)
    angular = _param(graph, ANGULAR)
    table = LIMITS.get((model, graph.ros_version)) or LIMITS.get((model, 0)) or DEFAULT_LIMITS
    if linear and angular:
        return linear[1], angular[1], f"params {linear[0]}, {angular[0]}"
    return table


def _param(graph: Graph, pattern: re.Pattern) -> tuple[str, float] | None:
    for name, text in graph.params.items():
        if pattern.search(name):
            value = decode_param(text)
            if finite(value) and value > 0:  # a robot's NaN, Infinity or 1e400 is no limit
                return name, float(value)
    return None
