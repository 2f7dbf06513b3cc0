"""The simulator's battery and synthetic camera, read through rosbridge as the portal reads them."""

import asyncio
import base64
import struct
import zlib

import pytest

from robots.rosbridge import RosbridgeClient
from simworker import camera
from simworker.testing import running_world

pytestmark = pytest.mark.timeout(60)


async def _messages(url: str, topic: str, type_: str, count: int, publish=None) -> list[dict]:
    """The first `count` messages of a topic (publishing `publish` (topic, type, msg) every 0.1 s meanwhile)."""
    got: list[dict] = []
    async with RosbridgeClient(url) as client:
        await client.subscribe(topic, type_, got.append)
        for _ in range(300):
            if len(got) >= count:
                break
            if publish is not None:
                await client.publish(*publish)
            await asyncio.sleep(0.1)
    return got


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_tiago_publishes_camera_frames_that_show_its_walls():
    with running_world("paper", endpoints=["tiago"]) as world:
        frames = asyncio.run(
            _messages(
                world.urls["tiago"], "/xtion/rgb/image_raw/compressed", "sensor_msgs/CompressedImage", 2
            )
        )
    assert len(frames) >= 2
    images = [base64.b64decode(frame["data"]) for frame in frames]
    assert all(_png_size(image) == (camera.WIDTH, camera.HEIGHT) for image in images)
    assert "png" in frames[0]["format"]
    assert images[0] != images[1]  # each frame its own (the running block)
    pixels = zlib.decompress(images[0][images[0].index(b"IDAT") + 4 : -16])
    assert len(pixels) == camera.HEIGHT * (1 + 3 * camera.WIDTH)


def test_render_draws_a_near_wall_taller_than_a_far_one():
    def wall_rows(distance):
        image = camera.render([distance] * camera.RAYS.samples, 0)
        rows = zlib.decompress(image[image.index(b"IDAT") + 4 : -16])
        stride = 1 + 3 * camera.WIDTH
        column = [rows[1 + y * stride + 3 * 80 : 1 + y * stride + 3 * 80 + 3] for y in range(camera.HEIGHT)]
        return sum(1 for pixel in column if pixel not in (camera.SKY, camera.FLOOR))

    assert wall_rows(0.5) > wall_rows(3.0) > wall_rows(None) == 0


def test_turtlebot_battery_drains_faster_while_it_drives():
    twist = {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}
    with running_world("paper", endpoints=["turtlebot"]) as world:
        url = world.urls["turtlebot"]
        standing = asyncio.run(_messages(url, "/battery_state", "sensor_msgs/BatteryState", 3))
        driving = asyncio.run(
            _messages(
                url,
                "/battery_state",
                "sensor_msgs/BatteryState",
                3,
                ("/cmd_vel", twist, "geometry_msgs/Twist"),
            )
        )
    charge = [message["percentage"] for message in standing + driving]
    assert all(0.0 < value <= 1.0 for value in charge)
    assert charge == sorted(charge, reverse=True)  # it only drains
    assert (
        standing[0]["percentage"] - standing[-1]["percentage"]
        < driving[0]["percentage"] - driving[-1]["percentage"]
    )
