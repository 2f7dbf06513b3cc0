"""The ROS graph each simulated robot shows: nodes, topics, services and params per model.

Names and types follow tests/data/robot_profiles.yaml. Every name is put under the robot's
namespace (e.g. `/robot1`), as a namespaced launch would.
"""

from __future__ import annotations

from fleetcore.catalog import Interface, ModelProfile, urdf

ROS1 = {
    "twist": "geometry_msgs/Twist",
    "odom": "nav_msgs/Odometry",
    "scan": "sensor_msgs/LaserScan",
    "joints": "sensor_msgs/JointState",
    "imu": "sensor_msgs/Imu",
    "tf": "tf2_msgs/TFMessage",
    "grid": "nav_msgs/OccupancyGrid",
    "pose": "geometry_msgs/PoseStamped",
    "pose_cov": "geometry_msgs/PoseWithCovarianceStamped",
    "empty": "std_srvs/Empty",
    "trigger": "std_srvs/Trigger",
    "setbool": "std_srvs/SetBool",
    "bool": "std_msgs/Bool",
    "diag": "diagnostic_msgs/DiagnosticArray",
}
ROS2 = {
    k: v.replace("/", "/srv/" if k in ("empty", "trigger", "setbool") else "/msg/") for k, v in ROS1.items()
}


def build_interface(profile: ModelProfile, ns: str, ros_version: int, stack: str, name: str) -> Interface:
    """Return the interface of a robot of this model, namespace and navigation stack."""
    builder = BUILDERS.get((profile.key, ros_version))
    if builder is None:
        raise ValueError(f"no ROS {ros_version} interface for model {profile.key!r}")
    iface = Interface()
    builder(iface, ns, stack)
    if stack == "move_base":
        _move_base(iface, ns, profile)
    elif stack == "nav2":
        _nav2(iface, ns, profile)
    iface.nav = stack or None
    description = urdf(name, profile)
    if ros_version == 1:
        iface.params[f"{ns}/robot_description"] = description
    else:
        iface.params[f"{ns}/robot_state_publisher:robot_description"] = description
    return iface


def _tb3_ros1(iface: Interface, ns: str, stack: str) -> None:
    t = ROS1
    iface.add(
        f"{ns}/turtlebot3_core",
        pubs=[
            (f"{ns}/odom", t["odom"]),
            (f"{ns}/joint_states", t["joints"]),
            (f"{ns}/imu", t["imu"]),
            (f"{ns}/battery_state", "sensor_msgs/BatteryState"),
            (f"{ns}/sensor_state", "turtlebot3_msgs/SensorState"),
            (f"{ns}/tf", t["tf"]),
        ],
        subs=[
            (f"{ns}/cmd_vel", t["twist"]),
            (f"{ns}/motor_power", t["bool"]),
            (f"{ns}/reset", "std_msgs/Empty"),
        ],
    )
    iface.add(f"{ns}/turtlebot3_lds", pubs=[(f"{ns}/scan", t["scan"])])
    iface.add(
        f"{ns}/turtlebot3_diagnostics",
        pubs=[("/diagnostics", t["diag"])],
        subs=[(f"{ns}/sensor_state", "turtlebot3_msgs/SensorState")],
    )
    iface.add(
        f"{ns}/robot_state_publisher",
        pubs=[(f"{ns}/tf", t["tf"]), (f"{ns}/tf_static", t["tf"])],
        subs=[(f"{ns}/joint_states", t["joints"])],
    )
    iface.cmd_inputs[f"{ns}/cmd_vel"] = 1000
    iface.odom_topics.append((f"{ns}/odom", "odom", "base_footprint"))
    iface.scan_topic = f"{ns}/scan"
    iface.nav_cmd_topic = f"{ns}/cmd_vel"


def _tb3_ros2(iface: Interface, ns: str, stack: str) -> None:
    t = ROS2
    iface.add(
        f"{ns}/turtlebot3_node",
        pubs=[
            (f"{ns}/odom", t["odom"]),
            (f"{ns}/joint_states", t["joints"]),
            (f"{ns}/imu", t["imu"]),
            (f"{ns}/battery_state", "sensor_msgs/msg/BatteryState"),
            (f"{ns}/magnetic_field", "sensor_msgs/msg/MagneticField"),
            (f"{ns}/sensor_state", "turtlebot3_msgs/msg/SensorState"),
            (f"{ns}/tf", t["tf"]),
        ],
        subs=[(f"{ns}/cmd_vel", t["twist"])],
        services=[
            (f"{ns}/motor_power", t["setbool"]),
            (f"{ns}/reset", t["trigger"]),
            (f"{ns}/sound", "turtlebot3_msgs/srv/Sound"),
            (f"{ns}/reset_odometry", t["trigger"]),
        ],
    )
    iface.add(f"{ns}/hlds_laser_publisher", pubs=[(f"{ns}/scan", t["scan"])])
    iface.add(
        f"{ns}/robot_state_publisher",
        pubs=[
            (f"{ns}/tf", t["tf"]),
            (f"{ns}/tf_static", t["tf"]),
            (f"{ns}/robot_description", "std_msgs/msg/String"),
        ],
        subs=[(f"{ns}/joint_states", t["joints"])],
    )
    iface.cmd_inputs[f"{ns}/cmd_vel"] = 1000
    iface.odom_topics.append((f"{ns}/odom", "odom", "base_footprint"))
    iface.scan_topic = f"{ns}/scan"
    iface.nav_cmd_topic = f"{ns}/cmd_vel"


def _husky_ros1(iface: Interface, ns: str, stack: str) -> None:
    t = ROS1
    mux = {
        f"{ns}/joy_teleop/cmd_vel": 10,
        f"{ns}/kb_teleop/cmd_vel": 9,
        f"{ns}/twist_marker_server/cmd_vel": 8,
        f"{ns}/cmd_vel": 1,
    }
    ctrl = f"{ns}/husky_velocity_controller"
    iface.add(
        f"{ns}/husky_node",
        pubs=[
            (f"{ctrl}/odom", t["odom"]),
            (f"{ns}/joint_states", t["joints"]),
            (f"{ns}/status", "husky_msgs/HuskyStatus"),
        ],
        subs=[(f"{ctrl}/cmd_vel", t["twist"])],
    )
    iface.add(
        f"{ns}/twist_mux",
        pubs=[(f"{ctrl}/cmd_vel", t["twist"]), ("/diagnostics", t["diag"])],
        subs=[*((k, t["twist"]) for k in mux), (f"{ns}/e_stop", t["bool"])],
    )
    iface.add(
        f"{ns}/ekf_localization",
        pubs=[(f"{ns}/odometry/filtered", t["odom"]), (f"{ns}/tf", t["tf"])],
        subs=[(f"{ctrl}/odom", t["odom"]), (f"{ns}/imu/data", t["imu"])],
        services=[(f"{ns}/set_pose", "robot_localization/SetPose")],
    )
    iface.add(f"{ns}/imu_filter_node", pubs=[(f"{ns}/imu/data", t["imu"])])
    iface.add(
        f"{ns}/robot_state_publisher",
        pubs=[(f"{ns}/tf", t["tf"]), (f"{ns}/tf_static", t["tf"])],
        subs=[(f"{ns}/joint_states", t["joints"])],
    )
    iface.add(f"{ns}/twist_marker_server", pubs=[(f"{ns}/twist_marker_server/cmd_vel", t["twist"])])
    iface.add(
        f"{ns}/joy_teleop/teleop_twist_joy",
        pubs=[(f"{ns}/joy_teleop/cmd_vel", t["twist"])],
        subs=[(f"{ns}/joy_teleop/joy", "sensor_msgs/Joy")],
    )
    iface.cmd_inputs.update(mux)
    iface.cmd_inputs[f"{ctrl}/cmd_vel"] = 1000
    iface.odom_topics += [
        (f"{ctrl}/odom", "odom", "base_link"),
        (f"{ns}/odometry/filtered", "odom", "base_link"),
    ]
    iface.nav_cmd_topic = f"{ns}/cmd_vel"


def _tiago_ros1(iface: Interface, ns: str, stack: str) -> None:
    t = ROS1
    mux = {
        "nav_vel": 10,
        "joy_vel": 100,
        "key_vel": 90,
        "tab_vel": 100,
        "marker_vel": 99,
        "phone_vel": 98,
        "rviz_joy_vel": 95,
        "servoing_cmd_vel": 20,
    }
    mux = {f"{ns}/{k}": v for k, v in mux.items()}
    ctrl = f"{ns}/mobile_base_controller"
    iface.add(
        f"{ns}/gazebo",
        pubs=[
            (f"{ctrl}/odom", t["odom"]),
            (f"{ns}/joint_states", t["joints"]),
            (f"{ns}/scan_raw", t["scan"]),
            (f"{ns}/ground_truth_odom", t["odom"]),
            (f"{ns}/tf", t["tf"]),
        ],
        subs=[(f"{ctrl}/cmd_vel", t["twist"])],
    )
    iface.add(
        f"{ns}/twist_mux",
        pubs=[(f"{ctrl}/cmd_vel", t["twist"])],
        subs=[*((k, t["twist"]) for k in mux), (f"{ns}/pause_navigation", t["bool"])],
    )
    iface.add(f"{ns}/laser_filter", pubs=[(f"{ns}/scan", t["scan"])], subs=[(f"{ns}/scan_raw", t["scan"])])
    # the head camera's image_transport republisher; frames are synthetic (simworker.camera)
    iface.add(
        f"{ns}/xtion/rgb/image_raw_compressed",
        pubs=[(f"{ns}/xtion/rgb/image_raw/compressed", "sensor_msgs/CompressedImage")],
    )
    iface.add(
        f"{ns}/robot_state_publisher",
        pubs=[(f"{ns}/tf", t["tf"]), (f"{ns}/tf_static", t["tf"])],
        subs=[(f"{ns}/joint_states", t["joints"])],
    )
    iface.add(f"{ns}/play_motion", services=[(f"{ns}/play_motion/is_movable", "play_motion_msgs/IsMovable")])
    iface.cmd_inputs.update(mux)
    iface.cmd_inputs[f"{ctrl}/cmd_vel"] = 1000
    iface.odom_topics.append((f"{ctrl}/odom", "odom", "base_footprint"))
    iface.scan_topic = f"{ns}/scan_raw"
    iface.nav_cmd_topic = f"{ns}/nav_vel"


def _spot_ros1(iface: Interface, ns: str, stack: str) -> None:
    t = ROS1
    s = f"{ns}/spot"
    triggers = [
        "claim",
        "release",
        "power_on",
        "power_off",
        "stand",
        "sit",
        "self_right",
        "stop",
        "locked_stop",
        "estop/hard",
        "estop/gentle",
        "estop/release",
        "undock",
    ]
    status = {
        "feet": "FootStateArray",
        "estop": "EStopStateArray",
        "leases": "LeaseArray",
        "metrics": "Metrics",
        "feedback": "Feedback",
    }
    iface.add(
        f"{s}/spot_ros",
        pubs=[
            (f"{s}/odometry", t["odom"]),
            (f"{s}/odometry/twist", "geometry_msgs/TwistWithCovarianceStamped"),
            (f"{s}/odometry_corrected", t["odom"]),
            (f"{ns}/joint_states", t["joints"]),
            (f"{ns}/tf", t["tf"]),
            *((f"{s}/status/{k}", f"spot_msgs/{v}") for k, v in status.items()),
        ],
        subs=[(f"{s}/cmd_vel", t["twist"]), (f"{s}/go_to_pose", t["pose"])],
        services=[
            *((f"{s}/{k}", t["trigger"]) for k in triggers),
            (f"{s}/allow_motion", t["setbool"]),
            (f"{s}/stair_mode", t["setbool"]),
            (f"{s}/velocity_limit", "spot_msgs/SetVelocity"),
            (f"{s}/locomotion_mode", "spot_msgs/SetLocomotion"),
            (f"{s}/posed_stand", "spot_msgs/PosedStand"),
        ],
    )
    iface.add(
        f"{ns}/robot_state_publisher",
        pubs=[(f"{ns}/tf_static", t["tf"])],
        subs=[(f"{ns}/joint_states", t["joints"])],
    )
    iface.cmd_inputs[f"{s}/cmd_vel"] = 1000
    iface.odom_topics += [(f"{s}/odometry", "odom", "body"), (f"{s}/odometry_corrected", "odom", "body")]
    iface.params.update(
        {
            f"{s}/spot_ros/loop_frequency": 50.0,
            f"{s}/spot_ros/robot_state_rate": 20.0,
            f"{s}/spot_ros/auto_claim": False,
            f"{s}/spot_ros/auto_stand": False,
        }
    )


def _nav_odometry(iface: Interface, t: dict) -> list[tuple[str, str]]:
    """The odometry the navigation stack listens to: the robot's last (most fused) odometry topic.

    Husky's move_base takes the EKF's /odometry/filtered, TIAGo's the base controller's odometry.
    """
    return [(iface.odom_topics[-1][0], t["odom"])] if iface.odom_topics else []


LOCAL_PLANNERS = {"tiago": "teb_local_planner/TebLocalPlannerROS"}  # robot_profiles: TIAGo's public sim
LOCAL_PLANNER = "dwa_local_planner/DWAPlannerROS"  # TurtleBot3's and Husky's move_base


def _move_base(iface: Interface, ns: str, profile: ModelProfile) -> None:
    """Add ROS 1 move_base, amcl and map_server (topics as robot_profiles common.ros1_navigation), with the local
    planner's dynamic_reconfigure server (its max_vel_x is what a speed word changes)."""
    t = ROS1
    mb = f"{ns}/move_base"
    plugin = LOCAL_PLANNERS.get(profile.key, LOCAL_PLANNER)
    local = f"{mb}/{plugin.rsplit('/', 1)[-1]}"
    iface.add(
        mb,
        pubs=[
            (f"{mb}/feedback", "move_base_msgs/MoveBaseActionFeedback"),
            (f"{mb}/status", "actionlib_msgs/GoalStatusArray"),
            (f"{mb}/result", "move_base_msgs/MoveBaseActionResult"),
            (f"{mb}/current_goal", t["pose"]),
            (f"{mb}/NavfnROS/plan", "nav_msgs/Path"),
            (iface.nav_cmd_topic, t["twist"]),
        ],
        subs=[
            (f"{mb}/goal", "move_base_msgs/MoveBaseActionGoal"),
            (f"{mb}/cancel", "actionlib_msgs/GoalID"),
            (f"{ns}/move_base_simple/goal", t["pose"]),
            (f"{ns}/map", t["grid"]),
            *_nav_odometry(iface, t),
        ],
        services=[
            (f"{mb}/make_plan", "nav_msgs/GetPlan"),
            (f"{mb}/clear_costmaps", t["empty"]),
            (f"{mb}/NavfnROS/make_plan", "nav_msgs/GetPlan"),
            (f"{mb}/set_parameters", "dynamic_reconfigure/Reconfigure"),
            (f"{local}/set_parameters", "dynamic_reconfigure/Reconfigure"),
        ],
    )
    iface.add(
        mb,
        pubs=[
            (f"{local}/parameter_updates", "dynamic_reconfigure/Config"),
            (f"{local}/parameter_descriptions", "dynamic_reconfigure/ConfigDescription"),
        ],
    )
    iface.add(
        f"{ns}/amcl",
        pubs=[(f"{ns}/amcl_pose", t["pose_cov"]), (f"{ns}/particlecloud", "geometry_msgs/PoseArray")],
        subs=[(f"{ns}/initialpose", t["pose_cov"]), (f"{ns}/map", t["grid"])],
        services=[
            (f"{ns}/global_localization", t["empty"]),
            (f"{ns}/request_nomotion_update", t["empty"]),
            (f"{ns}/set_map", "nav_msgs/SetMap"),
        ],
    )
    iface.add(
        f"{ns}/map_server",
        pubs=[(f"{ns}/map", t["grid"]), (f"{ns}/map_metadata", "nav_msgs/MapMetaData")],
        services=[(f"{ns}/static_map", "nav_msgs/GetMap"), (f"{ns}/change_map", "nav_msgs/LoadMap")],
    )
    iface.latched |= {
        f"{ns}/map",
        f"{ns}/amcl_pose",
        f"{local}/parameter_updates",
        f"{local}/parameter_descriptions",
    }
    iface.params.update(
        {
            f"{mb}/controller_frequency": 10.0,
            f"{mb}/planner_patience": 5.0,
            f"{mb}/base_global_planner": "navfn/NavfnROS",
            f"{mb}/base_local_planner": plugin,
            f"{local}/max_vel_x": profile.nav_speed,
            f"{ns}/amcl/min_particles": 500,
        }
    )


def _nav2(iface: Interface, ns: str, profile: ModelProfile) -> None:
    """Add nav2 humble (robot_profiles common.ros2_nav2_humble): bt_navigator with navigate_to_pose and
    navigate_through_poses, planner, controller (its speed_limit topic), smoother, lifecycle managers (their
    /diagnostics), amcl, map_server."""
    t = ROS2
    pubs, services = [], []
    for action, kind in (
        ("navigate_to_pose", "NavigateToPose"),
        ("navigate_through_poses", "NavigateThroughPoses"),
    ):
        act, typ = f"{ns}/{action}/_action", f"nav2_msgs/action/{kind}"
        pubs += [
            (f"{act}/feedback", f"{typ}_FeedbackMessage"),
            (f"{act}/status", "action_msgs/msg/GoalStatusArray"),
        ]
        services += [
            (f"{act}/send_goal", f"{typ}_SendGoal"),
            (f"{act}/cancel_goal", "action_msgs/srv/CancelGoal"),
            (f"{act}/get_result", f"{typ}_GetResult"),
        ]
    iface.add(f"{ns}/bt_navigator", pubs=pubs, subs=[(f"{ns}/goal_pose", t["pose"])], services=services)
    for manager in ("lifecycle_manager_navigation", "lifecycle_manager_localization"):
        iface.add(f"{ns}/{manager}", pubs=[("/diagnostics", t["diag"])])
    iface.add(f"{ns}/planner_server", pubs=[(f"{ns}/plan", "nav_msgs/msg/Path")])
    iface.add(
        f"{ns}/controller_server",
        pubs=[(f"{ns}/cmd_vel_nav", t["twist"]), (f"{ns}/local_plan", "nav_msgs/msg/Path")],
        subs=[*_nav_odometry(iface, t), (f"{ns}/speed_limit", "nav2_msgs/msg/SpeedLimit")],
    )
    iface.add(
        f"{ns}/velocity_smoother",
        pubs=[(f"{ns}/cmd_vel", t["twist"])],
        subs=[(f"{ns}/cmd_vel_nav", t["twist"])],
    )
    iface.add(
        f"{ns}/amcl",
        pubs=[(f"{ns}/amcl_pose", t["pose_cov"]), (f"{ns}/particle_cloud", "nav2_msgs/msg/ParticleCloud")],
        subs=[(f"{ns}/initialpose", t["pose_cov"]), (f"{ns}/map", t["grid"])],
        services=[
            (f"{ns}/reinitialize_global_localization", t["empty"]),
            (f"{ns}/request_nomotion_update", t["empty"]),
        ],
    )
    iface.add(
        f"{ns}/map_server",
        pubs=[(f"{ns}/map", t["grid"])],
        services=[
            (f"{ns}/map_server/map", "nav_msgs/srv/GetMap"),
            (f"{ns}/map_server/load_map", "nav2_msgs/srv/LoadMap"),
        ],
    )
    iface.latched |= {f"{ns}/map", f"{ns}/amcl_pose"}
    iface.params.update(
        {
            f"{ns}/map_server:frame_id": "map",
            f"{ns}/amcl:min_particles": 500,
            f"{ns}/bt_navigator:global_frame": "map",
            f"{ns}/controller_server:speed_limit_topic": "speed_limit",
            f"{ns}/controller_server:FollowPath.max_vel_x": profile.nav_speed,
        }
    )


BUILDERS = {
    ("turtlebot3_burger", 1): _tb3_ros1,
    ("turtlebot3_burger", 2): _tb3_ros2,
    ("husky", 1): _husky_ros1,
    ("tiago", 1): _tiago_ros1,
    ("spot", 1): _spot_ros1,
}
