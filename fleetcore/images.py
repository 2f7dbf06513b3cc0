"""A camera frame as rosbridge delivers it, made into an image a browser shows as it is (no Django).

A sensor_msgs/CompressedImage carries its PNG or JPEG whole (rosbridge sends uint8[] as base64); a raw
sensor_msgs/Image (rgb8, bgr8, mono8, rgba8, bgra8) is written out as a PNG. The format and size are read from
the image's own header, never from what the message says, so what is kept says what it holds.
"""

from __future__ import annotations

import base64
import binascii
import struct
import zlib
from dataclasses import dataclass

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
RAW_CHANNELS = {"rgb8": 3, "bgr8": 3, "mono8": 1, "rgba8": 4, "bgra8": 4}
PNG_COLOUR = {1: 0, 3: 2, 4: 6}  # channels -> PNG colour type: grey, RGB, RGBA
MAX_BYTES = 16 * 2**20  # a frame larger than this is refused, not kept


class FrameError(ValueError):
    """A frame that is no image we can keep; the message says why, for a person."""


@dataclass(frozen=True)
class Image:
    data: bytes
    format: str  # "png" | "jpeg"
    width: int
    height: int


def from_message(message: dict) -> Image:
    """The image of a sensor_msgs/CompressedImage or sensor_msgs/Image message; FrameError if there is none."""
    if not isinstance(message, dict):
        raise FrameError("the camera sent no message")
    data = _bytes(message.get("data"))
    if "encoding" in message:  # a raw sensor_msgs/Image
        data = _raw_png(message, data)
    if len(data) > MAX_BYTES:
        raise FrameError(f"a frame of {len(data) // 2**20} MB (at most {MAX_BYTES // 2**20} MB are kept)")
    return Image(data, *size(data))


def size(data: bytes) -> tuple[str, int, int]:
    """(format, width, height) from a PNG's or a JPEG's own header."""
    if data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR":
        width, height = struct.unpack(">II", data[16:24])
        return "png", width, height
    if data[:2] == b"\xff\xd8":
        return "jpeg", *_jpeg_size(data)
    raise FrameError("a frame that is neither a PNG nor a JPEG")


def png(width: int, height: int, rows: bytes, colour: int = 2) -> bytes:
    """An 8-bit PNG from its rows (each led by its filter byte); colour: 2 RGB, 0 grey, 6 RGBA."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, colour, 0, 0, 0)
    return (
        PNG_SIGNATURE + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows, 6)) + chunk(b"IEND", b"")
    )


def _bytes(data) -> bytes:
    """uint8[] as rosbridge sends it: base64 text in JSON, bytes in CBOR, or a list of numbers."""
    try:
        if isinstance(data, str):
            return base64.b64decode(data, validate=True)
        if isinstance(data, bytes | bytearray | list):
            return bytes(data)
    except (binascii.Error, ValueError, TypeError):
        pass
    raise FrameError("a frame whose data is not an image's bytes")


def _raw_png(message: dict, data: bytes) -> bytes:
    encoding = str(message.get("encoding", "")).lower()
    channels = RAW_CHANNELS.get(encoding)
    if channels is None:
        raise FrameError(f"a raw {encoding or 'unnamed'} image (only {', '.join(RAW_CHANNELS)} are kept)")
    try:
        width, height, step = (int(message.get(key) or 0) for key in ("width", "height", "step"))
    except (TypeError, ValueError):
        width = height = step = 0
    line = width * channels
    if width <= 0 or height <= 0 or step < line or len(data) < step * height:
        raise FrameError(f"a raw {width}x{height} image whose data does not fill it")
    rows = bytearray()
    for y in range(height):
        row = bytearray(data[y * step : y * step + line])
        if encoding.startswith("bgr"):
            row[0::channels], row[2::channels] = row[2::channels], row[0::channels]
        rows += b"\0" + row  # PNG filter: none
    return png(width, height, bytes(rows), PNG_COLOUR[channels])


def _jpeg_size(data: bytes) -> tuple[int, int]:
    """Width and height from a JPEG's start-of-frame segment (any SOFn; not DHT, JPG or DAC)."""
    at = 2
    while at + 9 <= len(data):
        if data[at] != 0xFF:
            break
        marker = data[at + 1]
        if marker == 0xFF:  # a fill byte
            at += 1
            continue
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            height, width = struct.unpack(">HH", data[at + 5 : at + 9])
            return width, height
        at += 2 + int.from_bytes(data[at + 2 : at + 4], "big")
    raise FrameError("a JPEG without a frame header")
