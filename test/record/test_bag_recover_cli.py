"""``vmas-ros bag-recover`` (vmas_ros.record.recover_cli): what it keeps, what it reports, what it refuses.

The damaged bags are real: a recorder writes to disk and the test copies the
file while it is still open (what a SIGKILL leaves: finished chunks, no
summary, no footer), or cuts a finished file short. The recovered files are
read back with rosbags, independently of our writer. The command on a bag of
a SIGKILLed sim_node process is tested in test/ros/test_faults_signals.py.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock

from test.record.bag_helpers import _pose_bytes
from vmas_ros.record import McapRecorder
from vmas_ros.record.recover_cli import default_output, main

REPO = Path(__file__).resolve().parents[2]
MS = 1_000_000
CHUNK = 4096


def _clock(i: int) -> bytes:
    msg = Clock()
    msg.clock.nanosec = i * MS
    return serialize_message(msg)


def _killed_bag(tmp_path: Path, steps: int = 400) -> Path:
    """A bag as a SIGKILL leaves it: the file of a recorder that is still open, copied aside."""
    live, killed = tmp_path / "live.mcap", tmp_path / "killed.mcap"
    recorder = McapRecorder(live, chunk_size=CHUNK)
    for i in range(steps):
        recorder.write("/pose", "geometry_msgs/msg/PoseStamped", None, i * MS, serialized=_pose_bytes(i))
        recorder.write("/clock", "rosgraph_msgs/msg/Clock", None, i * MS, serialized=_clock(i))
    shutil.copyfile(live, killed)  # the open chunk is only in the recorder's memory
    recorder.close()
    live.unlink()
    return killed


def _read(path: Path) -> dict:
    """topic -> list of log times, read by rosbags (which refuses an unfinished file)."""
    topics: dict = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, timestamp, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)
            topics.setdefault(connection.topic, []).append(timestamp)
    return topics


def test_recovers_all_finished_chunks_and_reports_per_topic(tmp_path, capsys):
    killed = _killed_bag(tmp_path)
    out = tmp_path / "fixed.mcap"
    assert main([str(killed), str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    topics = _read(out)
    assert report["topics"] == {t: len(v) for t, v in topics.items()}
    assert report["complete"] is False and report["chunks"] >= 10
    assert report["bytes_used"] <= report["bytes_total"] == killed.stat().st_size
    # a prefix of what was written, both topics in step, and at most one chunk lost
    assert topics["/pose"] == [i * MS for i in range(len(topics["/pose"]))]
    assert abs(len(topics["/pose"]) - len(topics["/clock"])) <= 1
    per_step = len(_pose_bytes(0)) + len(_clock(0)) + 2 * 31  # message records of one step
    assert len(topics["/pose"]) >= 400 - CHUNK / per_step - 1
    assert report["first_log_time_ns"] == 0 and report["last_log_time_ns"] == max(topics["/pose"][-1], topics["/clock"][-1])


def test_text_report_says_what_was_kept_and_lost(tmp_path, capsys):
    killed = _killed_bag(tmp_path)
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(killed.read_bytes()[:-100])  # and cut inside the last chunk written
    assert main([str(truncated)]) == 0
    text = capsys.readouterr().out
    out = default_output(truncated)
    assert out.name == "truncated.recovered.mcap" and out.is_file()
    kept = _read(out)
    assert f"  /pose: {len(kept['/pose'])}" in text and f"  /clock: {len(kept['/clock'])}" in text
    assert "lost: " in text and f"of {truncated.stat().st_size} bytes" in text
    assert "reading stopped at byte" in text and "_Truncated" in text


def test_complete_input_loses_nothing(tmp_path, capsys):
    path = tmp_path / "whole.mcap"
    with McapRecorder(path, chunk_size=CHUNK) as recorder:
        for i in range(50):
            recorder.write("/pose", "geometry_msgs/msg/PoseStamped", None, i * MS, serialized=_pose_bytes(i))
    assert main([str(path), str(tmp_path / "copy.mcap")]) == 0
    assert "the input was complete" in capsys.readouterr().out
    assert _read(tmp_path / "copy.mcap") == _read(path)


def test_refuses_to_overwrite_without_force(tmp_path, capsys):
    killed = _killed_bag(tmp_path, steps=100)
    out = tmp_path / "out.mcap"
    out.write_bytes(b"precious")
    assert main([str(killed), str(out)]) == 2
    assert f"{out} exists; pass --force" in capsys.readouterr().err
    assert out.read_bytes() == b"precious"
    assert main([str(killed), str(out), "--force"]) == 0
    assert "/pose" in _read(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["killed.mcap", "out.mcap"], "no temporary file left"


def test_refuses_to_write_over_its_input(tmp_path, capsys):
    killed = _killed_bag(tmp_path, steps=100)
    before = killed.read_bytes()
    for argv in ([str(killed), str(killed)], [str(killed), str(killed), "--force"],
                 [str(killed), str(tmp_path / "." / "killed.mcap"), "--force"]):
        assert main(argv) == 2
        assert "OUT is the input" in capsys.readouterr().err
    assert killed.read_bytes() == before


@pytest.mark.parametrize("case", ["missing", "not_mcap", "empty", "directory", "no_out_dir"])
def test_clear_errors_name_the_path(tmp_path, capsys, case):
    path = tmp_path / "input.mcap"
    out = tmp_path / "out.mcap"
    expected = {"missing": f"{path}: no such file", "not_mcap": f"{path} is not an MCAP file",
                "empty": f"{path}: empty file, nothing to recover", "directory": f"{path}: a folder without NAME_<n>.mcap files, not a bag folder",
                "no_out_dir": f"{tmp_path / 'nowhere'}: no such directory"}[case]
    if case == "not_mcap":
        path.write_text("a text file, not a bag\n")
    elif case == "empty":
        path.write_bytes(b"")
    elif case == "directory":
        path.mkdir()
    elif case == "no_out_dir":
        path = _killed_bag(tmp_path, steps=10)
        out = tmp_path / "nowhere" / "out.mcap"
    assert main([str(path), str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vmas-ros bag-recover: ") and expected in err, err
    assert not out.exists() and not list(tmp_path.glob("*.partial")) and not list(tmp_path.glob(".*partial"))


def test_runs_as_a_module(tmp_path):
    killed = _killed_bag(tmp_path, steps=100)
    result = subprocess.run([sys.executable, "-m", "vmas_ros.record.recover_cli", str(killed), "--json"],
                            cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["output"] == str(default_output(killed)) and report["messages"] > 0
    assert sum(len(v) for v in _read(default_output(killed)).values()) == report["messages"]
