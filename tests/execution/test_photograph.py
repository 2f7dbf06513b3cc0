"""The photograph action end to end against the simulator: "tiago, take a photo" keeps a frame of TIAGo's
(synthetic) Xtion with the instruction, and nothing moves; a camera that sends no frame fails the step in words."""

import math
import struct
import threading

import pytest

from alerts.models import Alert
from execution import handlers
from execution.instructions import submit
from execution.models import Photo
from robots.models import Robot
from robots.rosbridge import sync
from simworker import camera
from simworker.testing import running_world
from tests.execution.conftest import register
from tests.execution.helpers import wait_final, wait_for

XTION = "/xtion/rgb/image_raw/compressed"
pytestmark = [pytest.mark.timeout(120), pytest.mark.usefixtures("seeded_ontology")]


@pytest.fixture
def tiago_world(executor):
    """The paper world with TIAGo alone registered, at twice real time."""
    with running_world("paper", endpoints=["tiago"], time_scale=2.0) as sim:
        sim.robots = register(sim, ["tiago"])
        yield sim


class Odometry:
    """Every pose and speed TIAGo's own odometry reports while watched."""

    def __init__(self, robot: Robot) -> None:
        odometry = robot.bindings.get(action="odometry")
        self.client = sync.get_client(robot.endpoint)
        self.lock, self.poses, self.speeds = threading.Lock(), [], []
        self.sub = self.client.subscribe(odometry.target, odometry.message_type, self._on)

    def _on(self, msg: dict) -> None:
        position, twist = msg["pose"]["pose"]["position"], msg["twist"]["twist"]
        with self.lock:
            self.poses.append((position["x"], position["y"]))
            self.speeds.append(abs(twist["linear"]["x"]) + abs(twist["angular"]["z"]))

    def close(self) -> tuple[list, list]:
        self.client.unsubscribe(self.sub)
        with self.lock:
            return list(self.poses), list(self.speeds)


def test_tiago_takes_a_photo_keeps_the_png_and_does_not_move(tiago_world, fleet_admin):
    tiago = Robot.objects.get(name="tiago")
    assert tiago.bindings.get(action="camera").target == XTION
    before = tiago_world.pose("tiago")
    watch = Odometry(tiago)
    try:
        done = wait_final(submit("tiago, take a photo", fleet_admin), timeout=60)
    finally:
        poses, speeds = watch.close()
    assert done.status == "succeeded", done.outcome
    assert f"took a photo ({camera.WIDTH}×{camera.HEIGHT} PNG)" in done.outcome

    (photo,) = Photo.objects.filter(execution__instruction=done)
    image = bytes(photo.image)
    assert image[:8] == b"\x89PNG\r\n\x1a\n" and image[12:16] == b"IHDR"
    assert struct.unpack(">II", image[16:24]) == (camera.WIDTH, camera.HEIGHT) == (photo.width, photo.height)
    assert (photo.format, photo.execution.robot, photo.topic) == ("png", tiago, XTION)

    assert poses and max(math.dist(poses[0], p) for p in poses) < 1e-3, poses  # its odometry: still
    assert max(speeds) < 1e-3, speeds
    assert math.dist(before[:2], tiago_world.pose("tiago")[:2]) < 1e-3  # and the simulated body


def test_a_camera_that_sends_no_frame_fails_the_step_with_the_reason(tiago_world, fleet_admin, monkeypatch):
    monkeypatch.setattr(handlers, "PHOTO_WAIT_S", 1.0)
    Robot.objects.get(name="tiago").bindings.filter(action="camera").update(target="/xtion/rgb/silent")
    done = wait_final(submit("take a picture with tiago", fleet_admin), timeout=60)
    assert done.status == "failed", done.outcome
    assert "tiago: no photo (no frame from /xtion/rgb/silent within 1 s)" in done.outcome
    assert not Photo.objects.exists()
    # the runner raises the step's alert after the instruction settles: seen, and its write done before the
    # test's tables are emptied (that write and the teardown's TRUNCATE deadlocked once)
    failed = Alert.objects.filter(kind="step_failed", robot__name="tiago")
    alert = wait_for(failed.first, timeout=10, what="the failed step's alert")
    assert "no photo (no frame from /xtion/rgb/silent within 1 s)" in alert.message


def test_a_photo_said_with_a_trip_is_taken_at_the_destination(tiago_world, fleet_admin):
    done = wait_final(submit("tiago, go to G and take a photo", fleet_admin), timeout=100)
    assert done.status == "succeeded", done.outcome
    assert f"took a photo ({camera.WIDTH}×{camera.HEIGHT} PNG) at G" in done.outcome, done.outcome
    assert math.dist(tiago_world.pose("tiago")[:2], (1.0, -1.0)) < 0.5
    assert Photo.objects.filter(execution__instruction=done).count() == 1
