"""fleetcore.jsontext reads robots' frames as Python's json does (rosbridge's own reader), only faster."""

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetcore import jsontext

ODOMETRY = (
    '{"op":"publish","topic":"/robot1/odom","msg":{"header":{"stamp":{"sec":12,"nanosec":5000},"frame_id":"odom"},'
    '"pose":{"pose":{"position":{"x":1.25,"y":-0.5,"z":0.0},"orientation":{"x":0.0,"y":0.0,"z":0.1,"w":0.99}},'
    '"covariance":[' + ",".join(["0.0"] * 36) + "]}}}"
)

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**63 - 1) | st.floats(allow_nan=False) | st.text(),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
    max_leaves=30,
)


@given(json_values)
def test_standard_json_reads_as_json_reads_it(value):
    text = json.dumps(value)
    assert jsontext.loads(text) == json.loads(text)
    assert jsontext.loads(text.encode()) == json.loads(text)


def test_an_odometry_frame_reads_as_json_reads_it():
    assert jsontext.loads(ODOMETRY) == json.loads(ODOMETRY)


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e400"])
def test_pythons_dialect_reads_as_rosbridge_writes_it(literal):
    """rosbridge's json.dumps writes a NaN pose bare; the frame must reach the pose gate, not fail to parse."""
    value = jsontext.loads('{"op":"publish","msg":{"x":' + literal + "}}")["msg"]["x"]
    expected = json.loads(literal)
    assert math.isnan(value) if math.isnan(expected) else value == expected


def test_a_lone_surrogate_reads_as_json_reads_it():
    assert jsontext.loads('{"name":"\\ud800"}') == {"name": "\ud800"}


@pytest.mark.parametrize("text", ["", "{", '{"op":}', "not json", "{'op': 'publish'}", '{"a":1} trailing'])
def test_what_json_refuses_raises_its_value_error(text):
    with pytest.raises(ValueError):
        jsontext.loads(text)


def test_nesting_past_what_json_reads_raises_its_recursion_error():
    with pytest.raises(RecursionError):
        jsontext.loads("[" * 100_000 + "]" * 100_000)


page_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
    max_leaves=30,
)


@given(page_values)
def test_what_a_page_is_sent_reads_back_as_it_was(value):
    assert json.loads(jsontext.dumps(value)) == value


def test_a_page_is_sent_null_for_nan_and_infinity_and_int_keys_as_json_writes_them():
    """A bare NaN makes a browser's JSON.parse throw; `json` with allow_nan=False raised and the push was lost."""
    text = jsontext.dumps({"battery": math.nan, "x": math.inf, "y": -math.inf, 7: [1.5]})
    assert json.loads(text) == {"battery": None, "x": None, "y": None, "7": [1.5]}
    assert "NaN" not in text and "Infinity" not in text


def test_what_orjson_refuses_is_written_or_refused_by_json():
    assert json.loads(jsontext.dumps({"name": "\ud800", "n": 2**70})) == {"name": "\ud800", "n": 2**70}
    with pytest.raises(TypeError):
        jsontext.dumps({"when": object()})
