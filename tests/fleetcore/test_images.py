"""Camera frames made into images a browser shows (fleetcore.images): compressed frames kept as they are, raw
ones written out as PNG, the size read from the image's own header."""

import base64
import struct
import zlib

import pytest

from fleetcore import images


def _pixels(png: bytes) -> bytes:
    """The rows of an unfiltered PNG written by images.png (one IDAT)."""
    (length,) = struct.unpack(">I", png[33:37])
    return zlib.decompress(png[41 : 41 + length])


def test_a_compressed_png_frame_is_kept_as_it_came_with_its_size_from_its_header():
    png = images.png(4, 3, b"".join(b"\0" + bytes(12) for _ in range(3)))
    image = images.from_message({"format": "png", "data": base64.b64encode(png).decode()})
    assert (image.data, image.format, image.width, image.height) == (png, "png", 4, 3)


def test_a_jpeg_frame_says_its_size_from_its_start_of_frame():
    app0 = b"\xff\xe0" + struct.pack(">H", 16) + b"JFIF\0" + bytes(9)
    sof0 = b"\xff\xc0" + struct.pack(">HBHHB", 11, 8, 240, 320, 1) + bytes(3)
    jpeg = b"\xff\xd8" + app0 + sof0 + b"\xff\xd9"
    image = images.from_message({"format": "jpeg", "data": list(jpeg)})
    assert (image.data, image.format, image.width, image.height) == (jpeg, "jpeg", 320, 240)


def test_a_raw_bgr8_image_becomes_an_rgb_png_without_its_row_padding():
    blue_then_red = bytes((255, 0, 0, 0, 0, 255)) + b"pad"  # one row of two bgr8 pixels, step 9
    data = base64.b64encode(blue_then_red).decode()
    image = images.from_message({"encoding": "bgr8", "width": 2, "height": 1, "step": 9, "data": data})
    assert (image.format, image.width, image.height) == ("png", 2, 1)
    assert _pixels(image.data) == b"\0" + bytes((0, 0, 255, 255, 0, 0))


@pytest.mark.parametrize(
    ("message", "reason"),
    [
        ({"format": "png", "data": base64.b64encode(b"not an image").decode()}, "neither a PNG nor a JPEG"),
        ({"format": "png", "data": "%%%"}, "not an image's bytes"),
        ({"encoding": "16UC1", "width": 1, "height": 1, "step": 2, "data": "AAA="}, "raw 16uc1 image"),
        ({"encoding": "rgb8", "width": 2, "height": 2, "step": 6, "data": "AAAA"}, "does not fill it"),
        ("frame", "no message"),
    ],
)
def test_a_frame_that_is_no_image_is_refused_with_a_reason(message, reason):
    with pytest.raises(images.FrameError, match=reason):
        images.from_message(message)
