"""Binding roles: what part of a robot's ROS interface serves each need, and how to recognise it (no Django).

One table for the whole portal. Registration scores topics against it (robots/identify.py), the ontology seeds
its editable topic keywords from it (interpreter/terms.py), a binding set by hand is checked against its types,
and the action registry (fleetcore/actions.py) names the roles each action needs.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Role:
    """One role a topic (or action server) can play for the portal.

    side: "sub" when the portal publishes and the robot subscribes (commands); "pub" when the robot publishes
    and the portal listens (sensors, state). canonical: the usual relative names, best first. keywords: words of
    a topic name that hint at the role, with their weight (the paper's Figure 12). synonyms: more words, weaker.
    """

    name: str
    types: frozenset[str]
    side: str
    canonical: tuple[str, ...]
    keywords: dict[str, float]
    synonyms: frozenset[str] = frozenset()
    description: str = ""


def _role(name, types, side, canonical, keywords, synonyms="", description="") -> Role:
    return Role(
        name,
        frozenset(types.split()),
        side,
        tuple(canonical.split()),
        {word: 1.0 for word in keywords.split()} | {k: v for k, v in _WEIGHTED.get(name, {}).items()},
        frozenset(synonyms.split()),
        description,
    )


_WEIGHTED = {"battery": {"power": 0.5}}

ROLES: dict[str, Role] = {
    role.name: role
    for role in (
        _role(
            "move",
            "geometry_msgs/Twist geometry_msgs/TwistStamped",
            "sub",
            "cmd_vel",
            "cmd vel cmd_vel velocity speed travel run",
            "drive motion twist go",
            "velocity commands",
        ),
        _role(
            "odometry", "nav_msgs/Odometry", "pub", "odom odometry", "odom odometry",
            "localization dead_reckoning", "where the wheels say the robot is",
        ),
        _role(
            "pose",
            "geometry_msgs/PoseWithCovarianceStamped geometry_msgs/PoseStamped",
            "pub",
            "amcl_pose",
            "amcl pose amcl_pose",
            "",
            "the localised pose on the map",
        ),
        _role(
            "navigate",
            "geometry_msgs/PoseStamped",
            "sub",
            "move_base_simple/goal goal_pose",
            "move_base map_server amcl goal move navigation navigate navigate_to_pose",
            "nav goto go_to",
            "goals for the robot's own navigation stack",
        ),
        _role("scan", "sensor_msgs/LaserScan", "pub", "scan", "scan laser lidar", "range sick hokuyo", "laser"),
        _role("map", "nav_msgs/OccupancyGrid", "pub", "map", "map map_server", "", "the occupancy grid"),
        _role(
            "initial_pose",
            "geometry_msgs/PoseWithCovarianceStamped",
            "sub",
            "initialpose",
            "initialpose initial initial_pose",
            "",
            "resets the localisation",
        ),
        _role(
            "battery", "sensor_msgs/BatteryState", "pub", "battery_state battery", "battery",
            "charge energy", "charge level",
        ),
        _role(
            "speed_limit",
            "nav2_msgs/SpeedLimit",
            "sub",
            "speed_limit",
            "speed limit speed_limit",
            "max_vel_x",
            "the navigation stack's speed limit (nav2's controller topic, or move_base's local planner)",
        ),
        _role(
            "dock",
            "irobot_create_msgs/Dock",
            "sub",
            "dock",
            "dock docking",
            "charger charging_station",
            "the robot's own docking action server",
        ),
        _role(
            "camera",
            "sensor_msgs/CompressedImage sensor_msgs/Image",
            "pub",
            "camera/image_raw/compressed camera/image_raw image_raw/compressed image_raw image_color",
            "camera image rgb xtion",
            "photo picture cam",
            "a colour camera's frames (what a photo is taken from)",
        ),
    )
}  # fmt: skip

ESSENTIAL = ("move", "odometry")  # a robot without these cannot be driven at all
NAV_ACTION_SERVERS = ("move_base", "navigate_to_pose")
# move_base's local planner takes its top speed (max_vel_x) through this service: the speed_limit role's ROS 1 form
RECONFIGURE = "dynamic_reconfigure/Reconfigure"


def accepts(role: str, message_type: str) -> bool:
    """Whether a topic of this type can play the role (ROS 1 and ROS 2 spellings of a type are one)."""
    spec = ROLES.get(role)
    return spec is not None and norm_type(message_type) in {norm_type(t) for t in spec.types}


def norm_type(message_type: str) -> str:
    """Spell a type as ROS 1 does: `pkg/msg/Type`, `pkg/srv/Type` and `pkg/action/Type` become `pkg/Type`."""
    return message_type.replace("/msg/", "/").replace("/srv/", "/").replace("/action/", "/")
