"""What rosbridge does to a frame on its way out: png and cbor compression, fragments past fragment_size.

Each follows rosbridge_library (`capabilities/subscribe.py`'s publish, `internal/pngcompression.py`,
`internal/cbor_conversion.py`, `capabilities/fragmentation.py`), quirks included: a fragment's `total` is
`(len - 1) / size + 1`, a float, as Python 3 divides (roslibjs floors it); a message without an id is
fragmented under id 0.
"""

from __future__ import annotations

import base64
import io
import json
import math
import struct

import cbor2
from PIL import Image

from simworker.messages import FLOATS, INTS, MsgDef, Registry

TAGGED = {  # cbor_conversion.TAGGED_ARRAY_FORMATS, by .msg type
    "uint16": (69, "<{}H"), "uint32": (70, "<{}I"), "uint64": (71, "<{}Q"), "int8": (72, "{}b"),
    "int16": (77, "<{}h"), "int32": (78, "<{}i"), "int64": (79, "<{}q"), "float32": (85, "<{}f"),
    "float64": (86, "<{}d"),
}  # fmt: skip


def fragments(text: str, size: int) -> list[str]:
    """The fragment frames of one serialized message longer than size."""
    try:
        mid = json.loads(text).get("id", 0)
    except ValueError:
        mid = 0
    total = ((len(text) - 1) / size) + 1
    return [
        json.dumps({"op": "fragment", "id": mid, "data": text[i : i + size], "num": n, "total": total})
        for n, i in enumerate(range(0, len(text), size))
    ]


def publish_op(topic: str, msg_json: str) -> str:
    """The publish op carrying an encoded message body, as rosbridge writes it (no id, no type)."""
    return f'{{"op":"publish","topic":"{topic}","msg":{msg_json}}}'


def compress(how: str, topic: str, msg_json: str, reg: Registry, definition: MsgDef | None) -> str | bytes:
    """A publish frame for a subscription asking for `how` (png or cbor; anything else: plain JSON)."""
    plain = publish_op(topic, msg_json)
    if how == "png":
        return json.dumps({"op": "png", "data": png(plain)})
    if how == "cbor":
        msg = json.loads(msg_json)
        if definition is not None:
            msg = cbor_values(reg, definition, msg)
        return cbor2.dumps({"op": "publish", "topic": topic, "msg": msg})
    return plain


def png(text: str) -> str:
    """pngcompression.encode: the text in a square RGB image padded with newlines, base64."""
    data = text.encode("utf-8")
    width = math.floor(math.sqrt(len(data) / 3.0)) or 1
    height = math.ceil((len(data) / 3.0) / width)
    padded = data + b"\n" * (width * height * 3 - len(data))
    buffer = io.BytesIO()
    Image.frombytes("RGB", (width, height), padded).save(buffer, "png")
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def cbor_values(reg: Registry, definition: MsgDef, msg: dict) -> dict:
    """extract_cbor_values: numeric sequences as tagged typed arrays, uint8[] as bytes."""
    out = {}
    for field in definition.fields:
        value = msg.get(field.name)
        if field.binary and isinstance(value, str):
            out[field.name] = base64.b64decode(value)
        elif field.array == 0 and field.type in TAGGED and isinstance(value, list):
            tag, fmt = TAGGED[field.type]
            cast = float if field.type in FLOATS else int
            out[field.name] = cbor2.CBORTag(tag, struct.pack(fmt.format(len(value)), *map(cast, value)))
        elif field.type in INTS or field.type in FLOATS or not isinstance(value, (dict, list)):
            out[field.name] = value
        else:
            sub = reg.message(field.type)
            if sub is None:
                out[field.name] = value
            elif isinstance(value, list):
                out[field.name] = [cbor_values(reg, sub, v) for v in value]
            else:
                out[field.name] = cbor_values(reg, sub, value)
    return out
