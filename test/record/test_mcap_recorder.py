"""McapRecorder: rosbag2-compatible MCAP files, read back by rosbags and mcap-ros2-support.

Every bag is checked with two independent readers: ``rosbags`` (AnyReader on the
``.mcap`` path, which builds its types from the embedded schemas, plus the
ROS2_JAZZY typestore) and ``mcap_ros2.reader.read_ros2_messages``.
"""
from __future__ import annotations

import glob
import math
import os
import signal
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import pytest
import yaml

# the record extra and rclpy are part of the test set-up: without them these tests must fail
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic

with warnings.catch_warnings():  # the module warns it is deprecated; read_ros2_messages is the brief's reader
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker, MarkerArray

from vmas_ros.record import (
    TF_MESSAGE_TYPE,
    McapRecorder,
    message_definition,
    qos_profile_yaml,
    recover,
    serialize_tf_message,
    split_path,
)
from vmas_ros.record.schemas import SEPARATOR, dependencies

REPO = Path(__file__).resolve().parents[2]
JAZZY = get_typestore(Stores.ROS2_JAZZY)
MS = 1_000_000  # ns


# ----------------------------------------------------------------- helpers
def _stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def _transforms(step: int, n: int = 3):
    out = []
    for k in range(n):
        tf = TransformStamped()
        tf.header.stamp = _stamp(step * 50 * MS)
        tf.header.frame_id = "w" * (k + step % 5)  # varying lengths: both CDR paddings occur
        tf.child_frame_id = f"agent_{k}/base_link"[: 1 + (k + step) % 17]
        tf.transform.translation.x = step + 0.25 * k
        tf.transform.translation.y = -1.5 * k
        tf.transform.rotation.z = math.sin(0.1 * k)
        tf.transform.rotation.w = math.cos(0.1 * k)
        out.append(tf)
    return out


STEPS = 20
TOPICS = {
    "/agent_0/pose": "geometry_msgs/msg/PoseStamped",
    "/agent_0/odom": "nav_msgs/msg/Odometry",
    "/agent_0/scan": "sensor_msgs/msg/LaserScan",
    "/world/markers": "visualization_msgs/msg/MarkerArray",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/agent_0/cmd_vel": "geometry_msgs/msg/Twist",
    "/tf": "tf2_msgs/msg/TFMessage",
}


def _write_sample(path: Path, **kwargs) -> McapRecorder:
    """STEPS steps of every sample topic, 50 ms apart; returns the closed recorder."""
    with McapRecorder(path, **kwargs) as rec:
        for step in range(STEPS):
            t = step * 50 * MS
            clock = Clock(clock=_stamp(t))
            rec.write("/clock", "rosgraph_msgs/msg/Clock", clock, t)
            pose = PoseStamped()
            pose.header.stamp, pose.header.frame_id = _stamp(t), "world"
            pose.pose.position.x, pose.pose.position.y = 0.5 * step, -0.25 * step
            pose.pose.orientation.w = 1.0
            rec.write("/agent_0/pose", "geometry_msgs/msg/PoseStamped", pose, t)
            odom = Odometry()
            odom.header.stamp, odom.header.frame_id, odom.child_frame_id = _stamp(t), "world", "agent_0/base_link"
            odom.twist.twist.linear.x = 0.1 * step
            rec.write("/agent_0/odom", "nav_msgs/msg/Odometry", odom, t)
            scan = LaserScan()
            scan.header.stamp, scan.header.frame_id = _stamp(t), "agent_0/base_link"
            scan.angle_min, scan.angle_max, scan.range_max = -math.pi, math.pi, 5.0
            scan.ranges = [1.0 + step, math.inf, 2.5, math.inf]
            rec.write("/agent_0/scan", "sensor_msgs/msg/LaserScan", scan, t)
            markers = MarkerArray()
            for k in range(2):
                m = Marker()
                m.header.frame_id, m.ns, m.id, m.type = "world", "entities", k, Marker.SPHERE
                m.pose.position.x = step + 10.0 * k
                m.scale.x = m.scale.y = m.scale.z = 0.1
                m.color.a = 1.0
                markers.markers.append(m)
            rec.write("/world/markers", "visualization_msgs/msg/MarkerArray", markers, t)
            twist = Twist()
            twist.angular.z = -0.5 * step
            # serialized bytes given: no second serialisation
            rec.write("/agent_0/cmd_vel", "geometry_msgs/msg/Twist", None, t, qos="best_effort",
                      serialized=serialize_message(twist))
            rec.write_raw("/tf", TF_MESSAGE_TYPE, serialize_tf_message(_transforms(step)), t + 1)
    return rec


def _check_sample_values(topic: str, step: int, msg) -> None:
    if topic == "/agent_0/pose":
        assert msg.pose.position.x == 0.5 * step and msg.pose.position.y == -0.25 * step
        assert msg.header.frame_id == "world"
    elif topic == "/agent_0/odom":
        assert msg.twist.twist.linear.x == pytest.approx(0.1 * step) and msg.child_frame_id == "agent_0/base_link"
    elif topic == "/agent_0/scan":
        ranges = list(msg.ranges)
        assert ranges[0] == 1.0 + step and ranges[2] == 2.5
        assert math.isinf(ranges[1]) and ranges[1] > 0 and math.isinf(ranges[3])
    elif topic == "/world/markers":
        assert [m.id for m in msg.markers] == [0, 1]
        assert [m.pose.position.x for m in msg.markers] == [step, step + 10.0]
    elif topic == "/clock":
        assert msg.clock.sec * 10**9 + msg.clock.nanosec == step * 50 * MS
    elif topic == "/agent_0/cmd_vel":
        assert msg.angular.z == -0.5 * step
    elif topic == "/tf":
        want = _transforms(step)
        assert len(msg.transforms) == len(want)
        for got, exp in zip(msg.transforms, want):
            assert got.header.frame_id == exp.header.frame_id and got.child_frame_id == exp.child_frame_id
            assert got.transform.translation.x == exp.transform.translation.x
            assert got.transform.translation.y == exp.transform.translation.y
            assert got.transform.rotation.z == exp.transform.rotation.z
            assert got.transform.rotation.w == exp.transform.rotation.w
    else:  # pragma: no cover
        raise AssertionError(topic)


def _read_rosbags(path: Path):
    """[(topic, msgtype, log_time, msg)] via AnyReader, cross-checked with the Jazzy typestore."""
    out = []
    with AnyReader([Path(path)]) as reader:
        for conn, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)  # types from the embedded schemas
            JAZZY.deserialize_cdr(raw, conn.msgtype)  # and from rosbags' own Jazzy definitions
            out.append((conn.topic, conn.msgtype, log_time, msg))
    return out


def _read_mcap_ros2(path: Path):
    return [(m.channel.topic, m.schema.name, m.log_time_ns, m.ros_msg)
            for m in read_ros2_messages(str(path), log_time_order=False)]


def _summary(path: Path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        return reader.get_header(), reader.get_summary()


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


# ------------------------------------------------------------- round trips
def test_round_trip_with_rosbags(tmp_path):
    path = tmp_path / "run.mcap"
    rec = _write_sample(path)
    assert rec.paths == [path] and rec.closed
    assert rec.message_counts == {topic: STEPS for topic in TOPICS}
    msgs = _read_rosbags(path)
    assert len(msgs) == STEPS * len(TOPICS)
    times = [t for _, _, t, _ in msgs]
    assert times == sorted(times)
    seen = {}
    for topic, msgtype, log_time, msg in msgs:
        assert TOPICS[topic] == msgtype
        step = seen.get(topic, 0)
        assert log_time == step * 50 * MS + (1 if topic == "/tf" else 0)
        _check_sample_values(topic, step, msg)
        seen[topic] = step + 1
    assert seen == {topic: STEPS for topic in TOPICS}
    with AnyReader([path]) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos["/agent_0/pose"][0].reliability.name == "RELIABLE"
    assert qos["/agent_0/cmd_vel"][0].reliability.name == "BEST_EFFORT"
    assert qos["/clock"][0].depth == 10 and qos["/clock"][0].durability.name == "VOLATILE"


def test_round_trip_with_mcap_ros2(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path, compression="lz4")
    msgs = _read_mcap_ros2(path)
    assert len(msgs) == STEPS * len(TOPICS)
    times = [t for _, _, t, _ in msgs]
    assert times == sorted(times)
    steps = {}
    for topic, schema, _, msg in msgs:
        assert TOPICS[topic] == schema
        _check_sample_values(topic, steps.get(topic, 0), msg)
        steps[topic] = steps.get(topic, 0) + 1
    assert steps == {topic: STEPS for topic in TOPICS}


def test_summary_statistics_and_channel_metadata(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path, chunk_size=2048)
    header, summary = _summary(path)
    assert header.profile == "ros2"
    stats = summary.statistics
    assert stats.message_count == STEPS * len(TOPICS)
    assert stats.channel_count == len(TOPICS) and stats.schema_count == len(set(TOPICS.values()))
    assert stats.message_start_time == 0 and stats.message_end_time == (STEPS - 1) * 50 * MS + 1
    assert stats.chunk_count == len(summary.chunk_indexes) > 1
    counts = {summary.channels[cid].topic: n for cid, n in stats.channel_message_counts.items()}
    assert counts == {topic: STEPS for topic in TOPICS}
    assert all(ci.message_index_offsets for ci in summary.chunk_indexes)
    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        schema = summary.schemas[channel.schema_id]
        assert schema.encoding == "ros2msg" and schema.name == TOPICS[channel.topic]
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        want = "best_effort" if channel.topic == "/agent_0/cmd_vel" else "reliable"
        assert profiles[0]["reliability"] == want
        assert profiles[0]["history"] == "keep_last" and profiles[0]["depth"] == 10
        assert profiles[0]["durability"] == "volatile"
        assert profiles[0]["deadline"] == {"sec": 9223372036, "nsec": 854775807}
    assert yaml.safe_load(qos_profile_yaml("best_effort"))[0]["reliability"] == "best_effort"
    with pytest.raises(ValueError):
        qos_profile_yaml("sometimes")


# ------------------------------------------------------ filter, split, errors
def test_topic_filter(tmp_path):
    path = tmp_path / "filtered.mcap"
    with McapRecorder(path, topics=["/agent_0/pose", "clock"]) as rec:  # "clock" means "/clock"
        assert rec.selects("/clock") and rec.selects("agent_0/pose") and not rec.selects("/tf")
        pose = PoseStamped()
        for i in range(5):
            assert rec.write("agent_0/pose", "geometry_msgs/msg/PoseStamped", pose, i)
            assert rec.write("/clock", "rosgraph_msgs/msg/Clock", Clock(), i)
            assert not rec.write("/agent_0/odom", "nav_msgs/msg/Odometry", Odometry(), i)
            assert not rec.write_raw("/tf", TF_MESSAGE_TYPE, b"ignored", i)
        # an ignored topic is not checked at all, not even its time
        assert not rec.write("/ignored", "geometry_msgs/msg/Twist", Twist(), 0)
    assert rec.message_counts == {"/agent_0/pose": 5, "/clock": 5}
    assert {t for t, _, _, _ in _read_rosbags(path)} == {"/agent_0/pose", "/clock"}


def _pose_bytes(i: int) -> bytes:
    pose = PoseStamped()
    pose.header.frame_id = "world"
    pose.pose.position.x = float(i)
    return serialize_message(pose)


def _check_split(rec: McapRecorder, total: int) -> list:
    """Every file is a complete bag; together they hold messages 0..total-1 in order."""
    xs, spans = [], []
    for k, path in enumerate(rec.paths):
        assert path == split_path(rec.paths[0], k)
        _, summary = _summary(path)
        assert summary.statistics.message_count > 0
        got = _read_rosbags(path)
        assert len(got) == summary.statistics.message_count
        assert len(_read_mcap_ros2(path)) == len(got)
        xs += [msg.pose.position.x for _, _, _, msg in got]
        spans.append((got[0][2], got[-1][2]))
    assert xs == [float(i) for i in range(total)]
    assert sum(rec.message_counts.values()) == total
    return spans


def test_split_by_size(tmp_path):
    path = tmp_path / "run.mcap"
    total, max_bytes = 1000, 20_000
    with McapRecorder(path, max_bytes=max_bytes, chunk_size=2048, compression="none") as rec:
        for i in range(total):
            rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, i * MS, serialized=_pose_bytes(i))
    assert [p.name for p in rec.paths[:3]] == ["run.mcap", "run_1.mcap", "run_2.mcap"]
    assert len(rec.paths) >= 5
    _check_split(rec, total)
    for p in rec.paths:  # the data section stays within max_bytes; the summary comes on top
        with open(p, "rb") as f:
            reader = make_reader(f)
            reader.get_summary()
        data_end = _data_section_size(p)
        assert data_end <= max_bytes, (p.name, data_end)
        assert data_end > max_bytes * 0.7 or p == rec.paths[-1]


def _data_section_size(path: Path) -> int:
    """Offset of the summary section (from the footer) = size of magic, header and data."""
    import struct
    raw = path.read_bytes()
    footer = raw[-8 - 29:-8]  # opcode, length, summary_start, summary_offset_start, crc
    assert footer[0] == 0x02
    (summary_start,) = struct.unpack_from("<Q", footer, 9)
    return summary_start


def test_split_by_duration(tmp_path):
    path = tmp_path / "timed.mcap"
    total = 500  # 10 ms apart: 4.99 s of log time
    with McapRecorder(path, max_duration_s=1.0) as rec:
        for i in range(total):
            rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, i * 10 * MS, serialized=_pose_bytes(i))
    spans = _check_split(rec, total)
    assert len(rec.paths) == 5
    for first, last in spans:
        assert last - first <= 1_000 * MS
    assert spans[0] == (0, 1_000 * MS)  # a file's log times span at most max_duration_s
    assert spans[1][0] == 1_010 * MS


def test_non_monotonic_log_time_raises(tmp_path):
    with McapRecorder(tmp_path / "t.mcap") as rec:
        rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 100)
        rec.write("/b", "geometry_msgs/msg/Twist", Twist(), 100)  # equal is fine
        with pytest.raises(ValueError, match=r"/a.*99 ns.*100 ns.*/b"):
            rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 99)
        with pytest.raises(ValueError, match="backwards"):
            rec.write_raw("/tf", TF_MESSAGE_TYPE, serialize_tf_message([]), 50)
        rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 101)
    assert rec.message_counts == {"/a": 2, "/b": 1}
    assert [t for _, _, t, _ in _read_rosbags(tmp_path / "t.mcap")] == [100, 100, 101]


def test_close_is_idempotent_and_final(tmp_path):
    path = tmp_path / "c.mcap"
    rec = McapRecorder(path)
    rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 1)
    rec.close()
    size = path.stat().st_size
    rec.close()
    rec.close()
    assert path.stat().st_size == size
    with pytest.raises(RuntimeError, match="closed"):
        rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 2)
    assert _summary(path)[1].statistics.message_count == 1
    # an empty recording is a valid, empty bag
    with McapRecorder(tmp_path / "empty.mcap"):
        pass
    assert _summary(tmp_path / "empty.mcap")[1].statistics.message_count == 0


def test_misuse_is_refused(tmp_path):
    path = tmp_path / "m.mcap"
    with McapRecorder(path) as rec:
        rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 1)
        with pytest.raises(ValueError, match="recorded as geometry_msgs/msg/Twist"):
            rec.write("/a", "geometry_msgs/msg/PoseStamped", PoseStamped(), 2)
        with pytest.raises(LookupError):
            rec.write_raw("/b", "no_pkg/msg/Nope", b"\x00\x01\x00\x00", 2)
        with pytest.raises(ValueError, match="qos"):
            rec.write("/c", "geometry_msgs/msg/Twist", Twist(), 2, qos="sometimes")
        with pytest.raises(ValueError, match="log_time_ns"):
            rec.write("/a", "geometry_msgs/msg/Twist", Twist(), -1)
        rec.write("/a", "geometry_msgs/msg/Twist", Twist(), 3)  # still usable
    assert rec.message_counts == {"/a": 2}
    with pytest.raises(FileExistsError):
        McapRecorder(path)
    (tmp_path / "m_1.mcap").write_bytes(b"stale split file")
    with McapRecorder(path, overwrite=True):
        pass
    assert not (tmp_path / "m_1.mcap").exists()
    with pytest.raises(ValueError):
        McapRecorder(tmp_path / "x.mcap", compression="brotli")
    with pytest.raises(ValueError):
        McapRecorder(tmp_path / "y.mcap", max_bytes=0)


def test_batch_and_flush(tmp_path):
    path = tmp_path / "b.mcap"
    mask_before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    with McapRecorder(path) as rec:
        with rec.batch():  # one step's messages: signals deferred once
            assert signal.SIGTERM in signal.pthread_sigmask(signal.SIG_BLOCK, [])
            for i in range(10):
                rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, i, serialized=_pose_bytes(i))
        assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask_before
        rec.flush()  # the open chunk is on disk now: what a kill would leave
        snapshot = tmp_path / "snapshot.mcap"
        snapshot.write_bytes(path.read_bytes())
        rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, 10, serialized=_pose_bytes(10))
    assert recover(snapshot, tmp_path / "r.mcap")["messages"] == 10
    assert _recovered_xs(tmp_path / "r.mcap") == [float(i) for i in range(10)]
    assert _summary(path)[1].statistics.message_count == 11


# ----------------------------------------------------------------- recovery
def _recovered_xs(path: Path) -> list:
    got = _read_rosbags(path)
    assert len(_read_mcap_ros2(path)) == len(got)
    return [msg.pose.position.x for _, _, _, msg in got]


def test_recover_truncated_file_at_any_offset(tmp_path):
    path = tmp_path / "full.mcap"
    with McapRecorder(path, chunk_size=1024) as rec:
        for i in range(300):
            rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, i * MS, serialized=_pose_bytes(i))
    raw = path.read_bytes()
    full = recover(path, tmp_path / "same.mcap")
    assert full["complete"] and full["messages"] == 300 and full["error"] is None
    previous = 0
    cut_path, out = tmp_path / "cut.mcap", tmp_path / "out.mcap"
    for cut in list(range(0, len(raw), max(1, len(raw) // 61))) + [len(raw) - 1]:
        cut_path.write_bytes(raw[:cut])
        report = recover(cut_path, out)
        xs = [m.ros_msg.pose.position.x for m in read_ros2_messages(str(out), log_time_order=False)]
        assert xs == [float(i) for i in range(len(xs))], cut  # a prefix, nothing invented
        assert report["messages"] == len(xs) >= previous
        previous = len(xs)
    assert previous == 300  # the data section was complete before the summary got cut
    assert _recovered_xs(out) == [float(i) for i in range(300)]  # rosbags agrees
    with pytest.raises(ValueError, match="not an MCAP"):
        cut_path.write_bytes(b"definitely not mcap")
        recover(cut_path, out)


def _child(code: str, *args, **popen):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code), *map(str, args)], env=env,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)


KILL_CHILD = """
    import sys
    from vmas_ros.record import McapRecorder
    from geometry_msgs.msg import PoseStamped
    path, chunk_size = sys.argv[1], int(sys.argv[2])
    rec = McapRecorder(path, chunk_size=chunk_size)
    msg = PoseStamped()
    msg.header.frame_id = "world"
    for i in range(5000):
        msg.pose.position.x = float(i)
        rec.write("/pose", "geometry_msgs/msg/PoseStamped", msg, 1_000_000 * i)
        if i + 1 == 2500:
            print("WROTE", i + 1, flush=True)
            sys.stdin.readline()  # SIGKILL arrives here, mid-way
    rec.close()
"""


def test_sigkill_mid_recording_then_recover(tmp_path):
    path, chunk_size = tmp_path / "killed.mcap", 4096
    proc = _child(KILL_CHILD, path, chunk_size)
    try:
        line = proc.stdout.readline()
        assert line.split() == ["WROTE", "2500"], line + proc.stderr.read()
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(timeout=10) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    with open(path, "rb") as f:  # no summary, no footer: a plain reader gives up
        with pytest.raises(Exception):
            make_reader(f).get_summary()
    out = tmp_path / "recovered.mcap"
    report = recover(path, out)
    assert not report["complete"] and report["error"]
    xs = _recovered_xs(out)
    assert report["messages"] == len(xs) > 0
    assert xs == [float(i) for i in range(len(xs))]
    assert _summary(out)[1].statistics.message_count == len(xs)
    per_message = len(_pose_bytes(0)) + 31  # a Message record in the chunk
    lost = 2500 - len(xs)
    # only the open chunk is lost: fewer messages than fit in one chunk
    assert 0 <= lost <= chunk_size // per_message + 1, (lost, chunk_size, per_message)
    print(f"\nSIGKILL after 2500 messages ({per_message} B records, chunk_size {chunk_size} B): "
          f"recovered {len(xs)}, lost {lost} (one chunk holds ~{chunk_size // per_message + 1})")


TERM_CHILD = """
    import signal, sys, time
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    from vmas_ros.record import McapRecorder
    from geometry_msgs.msg import PoseStamped
    rec = McapRecorder(sys.argv[1], chunk_size=4096)  # never closed here: atexit does it
    msg = PoseStamped()
    deadline = time.monotonic() + 30
    i = 0
    try:
        while time.monotonic() < deadline:
            msg.pose.position.x = float(i)
            rec.write("/pose", "geometry_msgs/msg/PoseStamped", msg, 1_000_000 * i)
            i += 1
            if i == 500:
                print("STARTED", flush=True)
    finally:
        print("COUNT", rec.message_count, flush=True)
    sys.exit(3)  # not reached when SIGTERM arrives
"""


def test_sigterm_with_sys_exit_handler_leaves_a_finished_bag(tmp_path):
    path = tmp_path / "terminated.mcap"
    proc = _child(TERM_CHILD, path)
    try:
        assert proc.stdout.readline().strip() == "STARTED"
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    count = int(out.split()[-1])
    assert count >= 500
    _, summary = _summary(path)
    assert summary is not None and summary.statistics.message_count == count
    xs = [msg.pose.position.x for _, _, _, msg in _read_rosbags(path)]
    assert xs == [float(i) for i in range(count)]
