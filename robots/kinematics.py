"""A robot's model and velocity limits from its graph (no Django).

Limits come from the base controller's params when the robot exposes them (ROS 1
`<ns>/mobile_base_controller/linear/x/max_velocity`, ROS 2 `<ns>/<controller>:linear.x.max_velocity`), else
from LIMITS below, taken from ../shared/reference/robot_profiles.yaml (each line names its entry).
"""

from __future__ import annotations

import re

from robots.discovery import Graph, decode_param, finite

# (model, ros_version or 0 for any) -> (max_linear m/s, max_angular rad/s, source in robot_profiles.yaml)
LIMITS = {
    ("turtlebot3_burger", 0): (0.22, 2.84, "turtlebot3_burger.teleop_limits"),
    ("turtlebot3_waffle", 0): (0.26, 1.82, "turtlebot3_waffle.teleop_limits"),
    ("husky", 1): (1.0, 2.0, "clearpath_husky.ros1.controller_limits"),
    ("husky", 2): (1.0, 1.0, "clearpath_husky.ros2_husky_repo_humble.controller"),
    ("tiago", 1): (1.0, 2.0944, "pal_tiago.ros1.controller_limits"),
    ("tiago", 2): (1.0, 1.05, "pal_tiago.ros2.controller_limits"),
    ("jackal", 0): (2.0, 4.0, "clearpath_jackal.ros1.controller_limits"),
    ("fetch", 0): (1.0, 4.5, "fetch.ros1.base_controller"),
    ("spot", 0): (0.5, 0.5, "boston_dynamics_spot_ros1_driver.velocity_limits_driver_defaults"),
}
DEFAULT_LIMITS = (0.22, 1.0, "default: the slowest model we know")

# Model signatures: a model key when the URDF name, or any node/topic name, contains one of the words.
SIGNATURES = (
    ("turtlebot3_waffle", ("turtlebot3_waffle", "waffle")),
    ("turtlebot3_burger", ("turtlebot3", "turtlebot")),
    ("husky", ("husky",)),
    ("tiago", ("tiago", "pmb2", "play_motion")),
    ("jackal", ("jackal",)),
    ("fetch", ("fetch",)),
    ("spot", ("spot_ros", "spot")),
)
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
