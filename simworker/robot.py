"""One simulated robot on its endpoint: graph entries, twist_mux, odometry and laser publishing."""

from __future__ import annotations

import base64
import json
import math
import zlib
from collections.abc import Callable
from functools import partial

from fleetcore.catalog import ModelProfile
from fleetcore.world import RobotSpec
from simworker import camera, diagnostics
from simworker.connection import Deferred
from simworker.graph import Graph
from simworker.interfaces import build_interface
from simworker.physics import Physics, RobotBody
from simworker.server import RosbridgeServer

MUX_TIMEOUT = 0.5  # twist_mux input timeout (s)
IDLE_DRAIN, DRIVE_DRAIN = 0.0001, 0.005  # battery fraction per second standing, and more per m/s driven
ZEROS36 = "[" + ",".join(["0.0"] * 36) + "]"


def number(value) -> float:
    """Return a JSON number as float; reject strings, bools, NaN and infinities like a typed ROS field."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise TypeError(f"expected a finite number, got {value!r}")
    return float(value)


def vector(msg: dict, key: str) -> tuple[float, float, float]:
    """Return (x, y, z) of a Vector3 field; missing fields default to 0 as rosbridge fills them."""
    vec = msg.get(key, {})
    if not isinstance(vec, dict):
        raise TypeError(f"{key} must be an object")
    return number(vec.get("x", 0.0)), number(vec.get("y", 0.0)), number(vec.get("z", 0.0))


class SimRobot:
    """Glue between a physics body and the rosbridge endpoint that shows the robot."""

    def __init__(
        self,
        spec: RobotSpec,
        profile: ModelProfile,
        body: RobotBody,
        physics: Physics,
        server: RosbridgeServer,
        clock: Callable[[], float],
        odom_noise: float = 0.0,
    ) -> None:
        self.spec, self.profile, self.body, self.physics, self.server = spec, profile, body, physics, server
        self.graph: Graph = server.graph
        self.clock = clock
        self.ns = spec.namespace.rstrip("/")
        self.iface = build_interface(profile, self.ns, self.graph.ros_version, spec.stack, spec.name)
        self.start = (spec.x, spec.y, spec.yaw)
        # Where the robot was spawned, as a Gazebo launch file passes it (-x -y -Y): the odometry origin on the map.
        # Real robots without such a param get their map pose from amcl_pose or from an initial pose a person sets.
        self.iface.params[f"{self.ns}/initial_pose"] = [spec.x, spec.y, spec.yaw]
        self.odom_noise = odom_noise
        self.drift = [0.0, 0.0, 0.0]
        self.odom_fault: str | None = None  # a test's bad odometry: "nan" (x is NaN), "jump" (1 km away)
        self.seq = 0
        self.mux_priority, self.mux_time = -1, -1e9
        self.navigator = None
        self._register()
        published = {
            topic: type_ for entry in self.iface.nodes.values() for topic, type_ in entry["pubs"].items()
        }
        self.battery_topic = next(
            (t for t, type_ in published.items() if type_.endswith("BatteryState")), None
        )
        # the laser's own topic, and any filter's output (e.g. TIAGo's laser_filter: /scan from /scan_raw)
        scans = [
            t for t, type_ in published.items() if type_.endswith("LaserScan") and t != self.iface.scan_topic
        ]
        self.scan_topics = [self.iface.scan_topic, *scans] if self.iface.scan_topic else []
        self.diagnostics_topic = next(
            (t for t, type_ in published.items() if type_.endswith("DiagnosticArray")), None
        )
        self.camera_topic = next(
            (t for t, type_ in published.items() if type_.endswith("CompressedImage")), None
        )
        self.charge = (
            0.95 - (zlib.crc32(spec.name.encode()) % 20) / 100
        )  # each robot its own, the same each run
        self.frames = 0
        self._odom_templates = [
            (t, self._odom_template(frame, child)) for t, frame, child in self.iface.odom_topics
        ]

    def _register(self) -> None:
        g = self.graph
        for node, entry in self.iface.nodes.items():
            for topic, type_ in entry["pubs"].items():
                g.add_publisher(node, topic, type_)
            for topic, type_ in entry["subs"].items():
                g.add_subscriber(node, topic, type_)
            for name, type_ in entry["services"].items():
                g.add_service(node, name, type_)
        g.params.update(self.iface.params)
        g.latched_topics |= self.iface.latched
        for topic, priority in self.iface.cmd_inputs.items():
            g.on_topic(topic, lambda msg, p=priority: self.on_twist(msg, p))
        description = f"{self.ns}/robot_description"
        if g.topic_types.get(description) == "std_msgs/msg/String":  # ROS 2: also a latched topic
            g.latched_topics.add(description)
            text = next(v for k, v in self.iface.params.items() if k.endswith(":robot_description"))
            self.server.publish(description, {"data": text})

    # ----- commands -----
    def on_twist(self, msg: dict, priority: int) -> None:
        """Apply a Twist from a twist_mux input unless a higher-priority input is still fresh."""
        lin, ang = vector(msg, "linear"), vector(msg, "angular")
        now = self.physics.time
        if priority < self.mux_priority and now - self.mux_time < MUX_TIMEOUT:
            return
        self.mux_priority, self.mux_time = priority, now
        self.body.command(lin[0], ang[2], lin[1])

    def drive(self, vx: float, wz: float) -> None:
        """Command the base as the navigation stack does: through its cmd_vel topic and the mux."""
        topic = self.iface.nav_cmd_topic
        msg = {"linear": {"x": vx, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": wz}}
        self.on_twist(msg, self.iface.cmd_inputs.get(topic, 1000))
        if self.server.subscribed(topic):
            self.server.publish(topic, msg)

    # ----- state -----
    def pose(self) -> tuple[float, float, float]:
        return self.body.pose()

    def odom_pose(self) -> tuple[float, float, float]:
        """Return the pose in the odom frame: the body's actual motion since its start pose, plus drift.

        This is what Gazebo's diff drive reports with odometrySource world (TurtleBot3's setting): it follows
        the simulated body exactly, so a robot held by a wall shows no wheel-slip drift unless noise is on.
        """
        x, y, yaw = self.body.pose()
        x0, y0, yaw0 = self.start
        c, s = math.cos(-yaw0), math.sin(-yaw0)
        dx, dy = x - x0, y - y0
        return c * dx - s * dy + self.drift[0], s * dx + c * dy + self.drift[1], yaw - yaw0 + self.drift[2]

    # ----- publishing -----
    def _odom_template(self, frame: str, child: str) -> str:
        if self.graph.ros_version == 1:
            head = f'{{"header":{{"seq":%d,"stamp":{{"secs":%d,"nsecs":%d}},"frame_id":"{frame}"}}'
        else:
            head = f'{{"header":{{"stamp":{{"sec":%d,"nanosec":%d}},"frame_id":"{frame}"}}'
        return (
            head + f',"child_frame_id":"{child}","pose":{{"pose":{{"position":{{"x":%.5f,"y":%.5f,"z":0.0}},'
            '"orientation":{"x":0.0,"y":0.0,"z":%.6f,"w":%.6f}},"covariance":' + ZEROS36 + "},"
            '"twist":{"twist":{"linear":{"x":%.4f,"y":%.4f,"z":0.0},"angular":{"x":0.0,"y":0.0,"z":%.4f}},'
            '"covariance":' + ZEROS36 + "}}"
        )

    def publish_odometry(self, t: float) -> None:
        """Publish nav_msgs/Odometry on every odom topic someone subscribes to."""
        server = self.server
        listened = [(topic, tpl) for topic, tpl in self._odom_templates if topic in server.subscribers]
        if not listened:
            return
        wanted = [(topic, tpl) for topic, tpl in listened if server.wants(topic)]
        pose = self.odom_pose() if wanted else None  # built only for a message that goes (before this drift)
        if self.odom_noise and self.body.vx:  # the drift moves all the same
            rng, k = self.physics.rng, self.odom_noise * abs(self.body.vx) * 0.05
            self.drift[0] += rng.gauss(0, k)
            self.drift[1] += rng.gauss(0, k)
            self.drift[2] += rng.gauss(0, k)
        self.seq += 1  # a throttled subscriber sees gaps in it, as from a real publisher
        if pose is None:
            return
        x, y, yaw = pose
        vx, vy, wz = self.body.twist()
        sec = int(t)
        stamp = (sec, int((t - sec) * 1e9))
        if self.graph.ros_version == 1:
            stamp = (self.seq, *stamp)
        x += {"nan": math.nan, "jump": 1000.0}.get(self.odom_fault or "", 0.0)
        values = (*stamp, x, y, math.sin(yaw / 2), math.cos(yaw / 2), vx, vy, wz)
        for topic, tpl in wanted:  # written only if it goes (a held one replaced by a newer never is)
            server.publish_text(topic, Deferred(partial(_odometry_text, tpl, values, math.isfinite(x))))

    def publish_scan(self, t: float) -> None:
        """Publish sensor_msgs/LaserScan on each scan topic someone subscribes to (one ray cast for all)."""
        laser = self.profile.laser
        wanted = [topic for topic in self.scan_topics if topic in self.server.subscribers]
        if laser is None or not wanted:
            return
        ranges = self.physics.scan(self.body, laser, noise=0.01 if self.odom_noise else 0.0)
        n = laser.samples
        msg = {
            "header": self.graph.header(laser.frame_id, t),
            "angle_min": laser.angle_min,
            "angle_max": laser.angle_max,
            "angle_increment": (laser.angle_max - laser.angle_min) / max(n - 1, 1),
            "time_increment": 0.0,
            "scan_time": 1.0 / laser.rate_hz,
            "range_min": laser.range_min,
            "range_max": laser.range_max,
            "ranges": ranges,
            "intensities": [],
        }
        text = json.dumps(msg, separators=(",", ":"))
        for topic in wanted:
            self.server.publish_text(topic, text)

    def publish_battery(self, t: float, dt: float) -> None:
        """Drain the battery by dt seconds of what the robot did, and publish sensor_msgs/BatteryState."""
        self.charge = max(0.0, self.charge - dt * (IDLE_DRAIN + DRIVE_DRAIN * abs(self.body.vx)))
        if self.battery_topic is None or self.battery_topic not in self.server.subscribers:
            return
        msg = {
            "header": self.graph.header("base_link", t),
            "voltage": round(11.1 + 1.5 * self.charge, 3), "current": -1.2, "charge": None,
            "capacity": None, "design_capacity": 1.8, "percentage": round(self.charge, 4),
            "power_supply_status": 2, "power_supply_health": 1, "power_supply_technology": 3, "present": True,
            "cell_voltage": [], "location": "", "serial_number": "",
        }  # fmt: skip
        self.server.publish_text(
            self.battery_topic, json.dumps(msg, separators=(",", ":")).replace("NaN", "null")
        )

    def publish_diagnostics(self, t: float) -> None:
        """Publish this robot's diagnostic_msgs/DiagnosticArray if someone subscribes (simworker.diagnostics)."""
        topic = self.diagnostics_topic
        if topic is None or topic not in self.server.subscribers:
            return
        message = diagnostics.array(self, self.graph.header("", t))
        self.server.publish_text(topic, json.dumps(message, separators=(",", ":")))

    def publish_camera(self, t: float) -> None:
        """Publish a synthetic sensor_msgs/CompressedImage (PNG) if someone subscribes (simworker.camera)."""
        topic = self.camera_topic
        if topic is None or topic not in self.server.subscribers:
            return
        self.frames += 1
        image = camera.render(self.physics.scan(self.body, camera.RAYS), self.frames)
        msg = {
            "header": self.graph.header("xtion_rgb_optical_frame", t),
            "format": "rgb8; png compressed bgr8",
        }
        msg["data"] = base64.b64encode(image).decode("ascii")  # rosbridge sends uint8[] as base64
        self.server.publish_text(topic, json.dumps(msg, separators=(",", ":")))


def _odometry_text(template: str, values: tuple, finite: bool) -> str:
    text = template % values
    return text if finite else text.replace("nan", "NaN")  # as rosbridge's json.dumps writes it: a bare NaN
