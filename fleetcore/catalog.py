"""Robot models the simulator knows: body, limits and the ROS interface each real robot shows.

Values come from tests/data/robot_profiles.yaml; each profile says which limits it took.
The interface (nodes, topics, services) is what the real robot's launch files give under rosbridge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# The portal's velocity limits per model, when a robot's params do not say (registration reads these; the
# simulator's models below take theirs from here too, so the two never drift apart).
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


def limit(model: str, ros_version: int = 0) -> tuple[float, float]:
    """(max linear m/s, max angular rad/s) of a model: its ROS version's entry, else the any-version one."""
    linear, angular, _ = LIMITS.get((model, ros_version)) or LIMITS.get((model, 0)) or DEFAULT_LIMITS
    return linear, angular


@dataclass(frozen=True)
class Laser:
    """A planar laser: topic (relative to the namespace), frame and Gazebo sensor settings."""

    topic: str
    frame_id: str
    samples: int
    angle_min: float
    angle_max: float
    range_min: float
    range_max: float
    rate_hz: float


@dataclass(frozen=True)
class ModelProfile:
    """Body and limits of one robot model (metres, kilograms, m/s, rad/s, m/s^2, rad/s^2)."""

    key: str
    drive: str  # "diff", "skid" or "legged"
    length: float
    width: float
    offset_x: float  # footprint centre ahead of base_footprint
    mass: float
    max_v: float
    min_v: float
    max_w: float
    acc_v: float
    acc_w: float
    max_vy: float = 0.0
    cmd_timeout: float = 0.5
    nav_speed: float = 0.22  # local-planner max_vel_x used by the simulated nav stack
    nav_turn: float = 1.0
    joints: tuple[str, ...] = ()
    joint_type: str = "continuous"
    laser: Laser | None = None
    limits_source: str = ""

    @property
    def inscribed_radius(self) -> float:
        return min(self.length, self.width) / 2

    @property
    def circumscribed_radius(self) -> float:
        return math.hypot(self.length / 2 + abs(self.offset_x), self.width / 2)


TB3_LASER = Laser("scan", "base_scan", 360, 0.0, 6.28319, 0.12, 3.5, 5.0)
TIAGO_LASER = Laser("scan_raw", "base_laser_link", 666, -1.91986, 1.91986, 0.05, 25.0, 10.0)
SPOT_LEGS = tuple(
    f"{leg}_{j}"
    for leg in ("front_left", "front_right", "rear_left", "rear_right")
    for j in ("hip_x", "hip_y", "knee")
)

MODELS = {
    "turtlebot3_burger": ModelProfile(
        key="turtlebot3_burger",
        drive="diff",
        length=0.146,  # footprint_ros1 x from -0.105 to 0.041
        width=0.21,
        offset_x=-0.032,
        mass=1.0,
        # teleop_limits (0.22 m/s, 2.84 rad/s) and the Gazebo diff drive's wheelAcceleration 1 rad/s^2 ...
        # ... is for the wheels; we take DWA acc_lim_x 2.5 / acc_lim_theta 3.2 as the body limits.
        max_v=limit("turtlebot3_burger")[0],
        min_v=-limit("turtlebot3_burger")[0],
        max_w=limit("turtlebot3_burger")[1],
        acc_v=2.5,
        acc_w=3.2,
        nav_speed=0.22,
        nav_turn=1.0,
        joints=("wheel_left_joint", "wheel_right_joint"),
        laser=TB3_LASER,
        limits_source="teleop_limits (speed), navigation.nav_limits acc_lim_x/acc_lim_theta (acceleration)",
    ),
    "husky": ModelProfile(
        key="husky",
        drive="skid",
        length=0.9874,
        width=0.5709,
        offset_x=0.0,
        mass=50.0,
        max_v=limit("husky", 1)[0],
        min_v=-limit("husky", 1)[0],
        max_w=limit("husky", 1)[1],
        acc_v=3.0,
        acc_w=6.0,
        cmd_timeout=0.25,
        nav_speed=0.5,
        nav_turn=1.0,
        joints=("front_left_wheel", "front_right_wheel", "rear_left_wheel", "rear_right_wheel"),
        limits_source="ros1.controller_limits of husky_velocity_controller; nav from DWAPlannerROS",
    ),
    "tiago": ModelProfile(
        key="tiago",
        drive="diff",
        length=0.55,  # round base, robot_radius 0.275: modelled as a circle
        width=0.55,
        offset_x=0.0,
        mass=70.0,
        max_v=limit("tiago", 1)[0],
        min_v=-0.2,
        max_w=limit("tiago", 1)[1],
        acc_v=1.0,
        acc_w=2.0944,
        cmd_timeout=0.25,
        nav_speed=0.5,
        nav_turn=0.6,
        joints=("wheel_left_joint", "wheel_right_joint"),
        laser=TIAGO_LASER,
        limits_source="ros1.controller_limits of mobile_base_controller; nav from nav_limits_teb",
    ),
    "spot": ModelProfile(
        key="spot",
        drive="legged",
        length=1.1,
        width=0.5,
        offset_x=0.0,
        mass=32.0,
        # driver defaults max_linear_velocity_x/y 0.5, max_angular_velocity_z 0.5; the driver sets
        # no acceleration limit, we take 1.0 m/s^2 and 1.0 rad/s^2 (the body's own smoothing).
        max_v=limit("spot")[0],
        min_v=-limit("spot")[0],
        max_w=limit("spot")[1],
        acc_v=1.0,
        acc_w=1.0,
        max_vy=0.5,
        joints=SPOT_LEGS,
        joint_type="revolute",
        limits_source="spot_ros velocity_limits_driver_defaults; acceleration assumed",
    ),
}


def model(key: str) -> ModelProfile:
    """Return the profile for a model key or raise KeyError naming the known ones."""
    try:
        return MODELS[key]
    except KeyError:
        raise KeyError(f"unknown robot model {key!r}; known: {', '.join(sorted(MODELS))}") from None


def urdf(name: str, profile: ModelProfile) -> str:
    """Return a small URDF: base_footprint, base_link and the model's wheel or leg joints."""
    links = [
        '  <link name="base_footprint"/>',
        f'  <link name="base_link"><collision><origin xyz="{profile.offset_x} 0 0"/>'
        f'<geometry><box size="{profile.length} {profile.width} 0.2"/>'
        "</geometry></collision></link>",
        '  <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/>'
        "</joint>",
    ]
    for i, joint in enumerate(profile.joints):
        child = joint.removesuffix("_joint") + "_link"
        side = 1 if ("left" in joint) else -1
        limit = (
            '<limit lower="-1.5" upper="1.5" effort="45" velocity="10"/>'
            if profile.joint_type == "revolute"
            else ""
        )
        links.append(f'  <link name="{child}"/>')
        links.append(
            f'  <joint name="{joint}" type="{profile.joint_type}"><parent link="base_link"/>'
            f'<child link="{child}"/><origin xyz="{0.1 * (i // 2):.2f} {side * profile.width / 2:.3f} 0"/>'
            f'<axis xyz="0 1 0"/>{limit}</joint>'
        )
    body = "\n".join(links)
    return f'<?xml version="1.0"?>\n<robot name="{name}">\n{body}\n</robot>\n'


@dataclass
class Interface:
    """What one robot exposes: nodes with their topics and services, inputs, outputs, params."""

    nodes: dict[str, dict[str, dict[str, str]]] = field(default_factory=dict)
    cmd_inputs: dict[str, int] = field(default_factory=dict)  # topic -> twist_mux priority
    odom_topics: list[tuple[str, str, str]] = field(default_factory=list)  # topic, frame, child frame
    scan_topic: str | None = None
    nav: str | None = None  # "move_base", "nav2" or None
    nav_cmd_topic: str | None = None
    params: dict[str, object] = field(default_factory=dict)
    latched: set[str] = field(default_factory=set)

    def add(self, node: str, pubs=(), subs=(), services=()) -> None:
        """Add a node's publications, subscriptions and services ((name, type) pairs)."""
        entry = self.nodes.setdefault(node, {"pubs": {}, "subs": {}, "services": {}})
        entry["pubs"].update(pubs)
        entry["subs"].update(subs)
        entry["services"].update(services)
