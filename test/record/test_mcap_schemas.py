"""McapRecorder's schemas and /tf serialisation: rosbag2's ``ros2msg`` text, read by both readers.

``message_definition`` builds the schema text rosbag2 writes (a message, then
each dependency under a separator line); ``serialize_tf_message`` writes
tf2_msgs/TFMessage without tf2_msgs. rosbags and mcap-ros2-support must parse
both (see bag_helpers.py for the readers).
"""
from __future__ import annotations

import glob
import os
import sys
import textwrap
from pathlib import Path

import pytest
from geometry_msgs.msg import PoseStamped
from mcap_ros2._dynamic import generate_dynamic
from rosbags.typesys import get_types_from_msg

from test.record.bag_helpers import JAZZY, _transforms
from vmas_ros.record import message_definition, serialize_tf_message
from vmas_ros.record.schemas import SEPARATOR, dependencies


# ------------------------------------------------------------------ schemas
def test_schema_text_is_rosbag2s_layout():
    text = message_definition("sensor_msgs/msg/LaserScan")
    own = (Path(sys.prefix) / "share/sensor_msgs/msg/LaserScan.msg").read_text()
    assert text.startswith(own.rstrip("\n") + "\n")
    blocks = text.split(SEPARATOR + "\n")
    assert len(SEPARATOR) == 80 and set(SEPARATOR) == {"="}
    assert [b.splitlines()[0] for b in blocks[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    assert message_definition("sensor_msgs/LaserScan") == text  # pkg/Name works too
    decoders = generate_dynamic("sensor_msgs/msg/LaserScan", text)
    assert {"sensor_msgs/msg/LaserScan", "std_msgs/Header", "builtin_interfaces/Time"} <= set(decoders)

    # each dependency once, depth-first in order of first use; relative names resolved
    marker = message_definition("visualization_msgs/msg/MarkerArray")
    names = [line[5:] for line in marker.splitlines() if line.startswith("MSG: ")]
    assert len(names) == len(set(names))
    assert names[:4] == [
        "visualization_msgs/Marker", "std_msgs/Header", "builtin_interfaces/Time", "geometry_msgs/Pose"]
    assert {"visualization_msgs/UVCoordinate", "visualization_msgs/MeshFile", "sensor_msgs/CompressedImage",
            "builtin_interfaces/Duration", "std_msgs/ColorRGBA"} <= set(names)
    assert "int32 SPHERE=2" in marker  # constants and comments stay


def test_field_type_resolution():
    text = textwrap.dedent("""\
        # a comment with a/Type in it
        Header header
        string<=5 short_name
        int32[<=3] bounded
        float64[9] fixed
        Foo[] foos
        other_pkg/Bar bar
        other_pkg/msg/Baz[4] baz
        uint8 CONSTANT=3
        string TEXT="#not a comment"
        Foo again
        """)
    assert dependencies("my_pkg", text) == [
        ("std_msgs", "Header"), ("my_pkg", "Foo"), ("other_pkg", "Bar"), ("other_pkg", "Baz")]
    # inside std_msgs, Header is std_msgs' own
    assert dependencies("std_msgs", "Header h\n") == [("std_msgs", "Header")]


def test_tf_message_definition_without_tf2_msgs():
    text = message_definition("tf2_msgs/msg/TFMessage")
    assert text.splitlines()[0] == "geometry_msgs/TransformStamped[] transforms"
    types = get_types_from_msg(text, "tf2_msgs/msg/TFMessage")
    for name in ("tf2_msgs/msg/TFMessage", "geometry_msgs/msg/TransformStamped", "geometry_msgs/msg/Transform"):
        assert types[name][1] == JAZZY.fielddefs[name][1]
    assert "tf2_msgs/msg/TFMessage" in generate_dynamic("tf2_msgs/msg/TFMessage", text)


def test_every_installed_definition_parses_in_both_readers():
    files = sorted(glob.glob(os.path.join(sys.prefix, "share", "*", "msg", "*.msg")))
    assert len(files) > 100
    for f in files:
        name = f"{Path(f).parts[-3]}/msg/{Path(f).stem}"
        text = message_definition(name)
        assert name in generate_dynamic(name, text)
        types = get_types_from_msg(text, name)
        if name in JAZZY.fielddefs and types[name][1]:  # rosbags pads empty messages with a member
            assert types[name][1] == JAZZY.fielddefs[name][1], name


def test_unknown_type_is_a_clear_error():
    with pytest.raises(LookupError, match="no_such_pkg/msg/Thing"):
        message_definition("no_such_pkg/msg/Thing")
    with pytest.raises(ValueError):
        message_definition("not a type")


# --------------------------------------------------------------- TF messages
@pytest.mark.parametrize("n", [0, 1, 2, 5])
def test_tf_message_cdr_matches_rosbags(n):
    for step in range(8):  # frame id lengths shift the first element's padding
        transforms = _transforms(step, n)
        data = serialize_tf_message(transforms)
        msg = JAZZY.deserialize_cdr(data, "tf2_msgs/msg/TFMessage")
        assert len(msg.transforms) == n
        for got, exp in zip(msg.transforms, transforms):
            assert got.header.frame_id == exp.header.frame_id and got.child_frame_id == exp.child_frame_id
            assert got.header.stamp.sec == exp.header.stamp.sec
            assert got.header.stamp.nanosec == exp.header.stamp.nanosec
            t, e = got.transform, exp.transform
            for a in "xyz":
                assert getattr(t.translation, a) == getattr(e.translation, a)
            for a in "xyzw":
                assert getattr(t.rotation, a) == getattr(e.rotation, a)
        assert JAZZY.serialize_cdr(msg, "tf2_msgs/msg/TFMessage") == data  # byte for byte


def test_tf_message_refuses_other_types():
    with pytest.raises(TypeError, match="TransformStamped"):
        serialize_tf_message([PoseStamped()])
