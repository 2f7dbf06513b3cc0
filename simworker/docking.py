"""The docking action of an iRobot Create 3 base (the TurtleBot 4's) on a simulated ROS 2 nav2 robot.

`<ns>/dock` (irobot_create_msgs/action/Dock) over rosbridge's send_action_goal, goal `{}`. The robot drives
there through its body's velocity like any command: the nav stack's own navigator takes it to a staging point
STAGING_M in front of the station, then a slow final approach turns it toward the dock pose, creeps onto it and
turns to the dock's heading. The action_result carries `{"is_docked": bool}` with status 4 (SUCCEEDED), 5
(CANCELED: cancel_action_goal, the client left, or a navigate goal took the base) or 6 (ABORTED: no plan, blocked,
too slow). A dock goal likewise ends a running navigate goal. The station is a static box in the physics, so the
laser sees it and a robot cannot drive through it; /dock_status says whether the robot sees it and is docked.
"""

from __future__ import annotations

import math

from fleetcore.geometry import wrap
from simworker.navigation import ABORTED, PREEMPTED, SUCCEEDED
from simworker.navstack import Nav2
from simworker.server import ActionGoal

DOCK_TYPE = "irobot_create_msgs/action/Dock"
STATUS_TYPE = "irobot_create_msgs/msg/DockStatus"
GOAL_SUCCEEDED, GOAL_CANCELED, GOAL_ABORTED = 4, 5, 6  # action_msgs/GoalStatus
STAGING_M = 0.5  # the final approach starts this far in front of the dock pose
APPROACH_SPEED = 0.06  # m/s on the final approach (the Create 3 creeps onto its dock)
TURN_SPEED, MIN_TURN = 0.6, 0.15  # rad/s while turning in place
XY_TOLERANCE, YAW_TOLERANCE = 0.02, 0.05  # where the final approach stops
HEADING_TOLERANCE = 0.05  # facing the dock pose well enough to creep toward it
DOCKED_XY, DOCKED_YAW = 0.05, 0.15  # is_docked: on the dock within these
STUCK_SECONDS = 8.0  # no progress on the final approach for this long: blocked, ABORTED
TIMEOUT_SECONDS = 240.0  # simulated seconds from goal to docked before ABORTED
SEE_RANGE, SEE_ANGLE = 1.5, 0.7  # the station's beacon is seen within this range and half-angle
STATION_DEPTH, STATION_WIDTH = 0.12, 0.25
STATION_CLEARANCE = 0.02  # between the robot's swept circle on its dock and the station
STATUS_TO_GOAL = {SUCCEEDED: GOAL_SUCCEEDED, PREEMPTED: GOAL_CANCELED, ABORTED: GOAL_ABORTED}


class DockServer:
    """One robot's dock station and its `dock` action server, driving the robot through its nav stack."""

    def __init__(self, stack: Nav2, dock: tuple[float, float, float]) -> None:
        self.stack, self.robot, self.dock = stack, stack.robot, dock
        self.name = f"{self.robot.ns}/dock"
        self.status_topic = f"{self.robot.ns}/dock_status"
        self.goal: ActionGoal | None = None
        self.phase: str | None = None  # "stage" (the navigator drives), "turn", "creep", "align"
        self.started = 0.0
        self.progress = (math.inf, 0.0)
        self.phases = {"turn": self._turn, "creep": self._creep, "align": self._align}
        self._register()
        self.robot.physics.add_fixture(*self.station(), STATION_DEPTH, STATION_WIDTH)
        stack.docking = self

    def _register(self) -> None:
        """Show the action server as Create 3's motion_control node does (hidden /_action/ entries)."""
        g, node, act = self.robot.graph, f"{self.robot.ns}/motion_control", f"{self.name}/_action"
        g.add_publisher(node, f"{act}/feedback", f"{DOCK_TYPE}_FeedbackMessage")
        g.add_publisher(node, f"{act}/status", "action_msgs/msg/GoalStatusArray")
        g.add_publisher(node, self.status_topic, STATUS_TYPE)
        g.add_service(node, f"{act}/send_goal", f"{DOCK_TYPE}_SendGoal")
        g.add_service(node, f"{act}/cancel_goal", "action_msgs/srv/CancelGoal")
        g.add_service(node, f"{act}/get_result", f"{DOCK_TYPE}_GetResult")
        self.robot.server.add_action(self.name, DOCK_TYPE, self._send_goal)

    def station(self) -> tuple[float, float, float]:
        """The station's centre and heading: just ahead of the docked robot, clear of it turning in place."""
        x, y, yaw = self.dock
        ahead = self.robot.profile.circumscribed_radius + STATION_CLEARANCE + STATION_DEPTH / 2
        return x + ahead * math.cos(yaw), y + ahead * math.sin(yaw), yaw

    @property
    def active(self) -> bool:
        return self.goal is not None

    # ----- state the robot can sense -----
    def is_docked(self) -> bool:
        x, y, yaw = self.robot.pose()
        dx, dy, dyaw = self.dock
        return math.dist((x, y), (dx, dy)) < DOCKED_XY and abs(wrap(yaw - dyaw)) < DOCKED_YAW

    def sees_dock(self) -> bool:
        """Whether the station is within the beacon's range and in front of the robot."""
        x, y, yaw = self.robot.pose()
        sx, sy, _ = self.station()
        return (
            math.dist((x, y), (sx, sy)) < SEE_RANGE
            and abs(wrap(math.atan2(sy - y, sx - x) - yaw)) < SEE_ANGLE
        )

    # ----- the action -----
    def _send_goal(self, goal: ActionGoal, args: dict) -> None:
        if args:
            goal.finish(f"Invalid goal: Dock has no goal fields, got {sorted(args)}", status=0, ok=False)
            return
        self.preempt()
        self.stack.nav.stop(PREEMPTED, "canceled: the robot is docking")  # a navigate goal ends CANCELED
        self.goal, self.started = goal, self.robot.physics.time
        goal.on_cancel = lambda g=goal: self._end(g, GOAL_CANCELED)
        if self.is_docked():
            self._end(goal, GOAL_SUCCEEDED)
        elif self._on_approach_line():
            self._enter("turn")
        else:
            self._stage(goal)

    def preempt(self) -> None:
        """End the running dock goal as CANCELED (another goal takes the base)."""
        if self.goal is not None:
            self._end(self.goal, GOAL_CANCELED)

    def _stage(self, goal: ActionGoal) -> None:
        """Let the navigator take the robot to the staging point in front of the station."""
        x, y, yaw = self.dock
        sx, sy = x - STAGING_M * math.cos(yaw), y - STAGING_M * math.sin(yaw)
        self.phase = "stage"
        self.stack.nav.start(sx, sy, None, on_done=lambda code, _text, g=goal: self._staged(g, code))

    def _staged(self, goal: ActionGoal, code: int) -> None:
        if goal is not self.goal:
            return
        if code == SUCCEEDED:
            self._enter("turn")
        else:
            self._end(goal, STATUS_TO_GOAL.get(code, GOAL_ABORTED))

    def _on_approach_line(self) -> bool:
        """Whether the robot already stands between the staging point and the dock (no need to stage)."""
        along, lateral = self._dock_frame()
        return 0.0 <= along <= STAGING_M + 0.05 and abs(lateral) < 0.05

    def _dock_frame(self) -> tuple[float, float]:
        """(distance still to go along the dock's heading, offset to its left) of the robot."""
        x, y, _ = self.robot.pose()
        dx, dy, dyaw = self.dock
        c, s = math.cos(dyaw), math.sin(dyaw)
        return c * (dx - x) + s * (dy - y), -s * (x - dx) + c * (y - dy)

    def _end(self, goal: ActionGoal, status: int) -> None:
        """Finish the goal once: stop the base, answer {"is_docked"} with the status."""
        if goal is not self.goal:
            return
        staging, self.goal, self.phase = self.phase == "stage", None, None
        if staging:
            self.stack.nav.stop(PREEMPTED, "docking ended")
        self.robot.drive(0.0, 0.0)
        goal.finish({"is_docked": self.is_docked()}, status=status)

    # ----- the final approach, at the controller frequency -----
    def tick(self, t: float) -> None:
        goal = self.goal
        if goal is None:
            return
        if self.robot.physics.time - self.started > TIMEOUT_SECONDS:
            self._end(goal, GOAL_ABORTED)
            return
        step = self.phases.get(self.phase)  # none while staging: the navigator drives
        if step is not None:
            step()
        if self.goal is goal and goal.want_feedback:
            goal.feedback({"sees_dock": self.sees_dock()})

    def _enter(self, phase: str) -> None:
        self.phase, self.progress = phase, (math.inf, self.robot.physics.time)

    def _bearing(self) -> tuple[float, float]:
        """Distance to the dock pose and the heading error toward it."""
        x, y, yaw = self.robot.pose()
        dx, dy, _ = self.dock
        return math.dist((x, y), (dx, dy)), wrap(math.atan2(dy - y, dx - x) - yaw)

    def _turn(self) -> None:
        dist, err = self._bearing()
        if dist < XY_TOLERANCE:
            self._enter("align")
        elif abs(err) < HEADING_TOLERANCE:
            self._enter("creep")
        elif self._making_progress(abs(err)):
            self._rotate(err)

    def _creep(self) -> None:
        dist, err = self._bearing()
        if dist < XY_TOLERANCE or self._dock_frame()[0] <= 0.0:
            self.robot.drive(0.0, 0.0)
            self._enter("align")
        elif abs(err) > 0.5:  # pushed off the line: face the dock again
            self._enter("turn")
        elif self._making_progress(dist):
            speed = min(APPROACH_SPEED, 0.5 * dist + 0.01)
            self.robot.drive(speed, max(-TURN_SPEED, min(TURN_SPEED, 1.5 * err)))

    def _align(self) -> None:
        err = wrap(self.dock[2] - self.robot.pose()[2])
        if abs(err) < YAW_TOLERANCE:
            self._end(self.goal, GOAL_SUCCEEDED)
        elif self._making_progress(abs(err)):
            self._rotate(err)

    def _rotate(self, err: float) -> None:
        self.robot.drive(0.0, math.copysign(max(MIN_TURN, min(TURN_SPEED, 1.5 * abs(err))), err))

    def _making_progress(self, measure: float) -> bool:
        """False (and the goal ABORTED) when the measure has not shrunk for STUCK_SECONDS: blocked."""
        best, since = self.progress
        now = self.robot.physics.time
        if measure < best - 0.005:
            self.progress = (measure, now)
        elif now - since > STUCK_SECONDS:
            self._end(self.goal, GOAL_ABORTED)
            return False
        return True

    # ----- /dock_status at 1 Hz -----
    def publish_status(self, t: float) -> None:
        """Publish irobot_create_msgs/DockStatus when someone listens."""
        if self.robot.server.subscribed(self.status_topic):
            self.robot.server.publish(
                self.status_topic,
                {
                    "header": self.robot.graph.header("base_link", t),
                    "dock_visible": self.sees_dock(),
                    "is_docked": self.is_docked(),
                },
            )
