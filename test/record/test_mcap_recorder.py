"""McapRecorder: rosbag2-compatible MCAP files, read back by rosbags and mcap-ros2-support.

Round trips, channel metadata and statistics, the topic filter, split files and
refused misuse. Every bag is checked with two independent readers (see
bag_helpers.py); schemas are in test_mcap_schemas.py, flushes, signals and
recovery in test_mcap_durability.py.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from geometry_msgs.msg import PoseStamped, Twist
from mcap.reader import make_reader
from nav_msgs.msg import Odometry
from rosbags.highlevel import AnyReader
from rosgraph_msgs.msg import Clock

from test.record.bag_helpers import (MS, STEPS, TOPICS, _check_sample_values, _pose_bytes, _read_mcap_ros2,
                                     _read_rosbags, _summary, _write_sample)
from vmas_ros.record import (
    TF_MESSAGE_TYPE, McapRecorder, RecordingFailed, qos_profile_yaml, serialize_tf_message, split_path,
)


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


def test_symlinks_are_never_written_through(tmp_path):
    """A link at the path (dangling or not) is refused, even with overwrite; nothing appears at its target."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    dangling, target = tmp_path / "dangling.mcap", elsewhere / "created.mcap"
    dangling.symlink_to(target)
    for overwrite in (False, True):
        with pytest.raises(FileExistsError, match=rf"{dangling} is a symlink to '{target}'.*give the real path"):
            McapRecorder(dangling, overwrite=overwrite)
        assert not target.exists() and dangling.is_symlink()
    victim = elsewhere / "keep.txt"
    victim.write_text("not a bag")
    linked = tmp_path / "linked.mcap"
    linked.symlink_to(victim)
    with pytest.raises(FileExistsError, match="is a symlink"):
        McapRecorder(linked, overwrite=True)
    assert victim.read_text() == "not a bag" and linked.is_symlink()


def test_a_split_file_that_is_a_symlink_is_never_written_through(tmp_path):
    path, target = tmp_path / "run.mcap", tmp_path / "elsewhere.mcap"
    (tmp_path / "run_1.mcap").symlink_to(target)  # left over, or planted before the start
    with pytest.raises(FileExistsError, match="run_1.mcap exists"):
        McapRecorder(path)
    with McapRecorder(path, overwrite=True, max_bytes=5_000) as rec:  # the stale link goes, its target is untouched
        assert not (tmp_path / "run_1.mcap").is_symlink()
        rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, 0, serialized=_pose_bytes(0))
        (tmp_path / "run_1.mcap").symlink_to(target)  # planted while recording, before the split
        with pytest.raises(RecordingFailed, match=r"writing \S+run_1.mcap: \S+run_1.mcap appeared while recording "
                                                  r"\(a symlink to"):
            for i in range(1, 200):
                rec.write("/pose", "geometry_msgs/msg/PoseStamped", None, i, serialized=_pose_bytes(i))
    assert not target.exists()
    assert _summary(path)[1].statistics.message_count > 0  # the first file is finished
