"""Bag folders (rosbag2's layout), overwriting rules and write errors of McapRecorder, without ROS nodes.

Folders are read by rosbags' folder ``Reader``; write errors are real: a
child process with a file size limit (``RLIMIT_FSIZE``: its writes fail with
EFBIG), and a folder removed while its recording is open.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from rosbags.rosbag2 import Reader

from test.record.bag_helpers import REPO, _pose_bytes
from vmas_ros.record import McapRecorder, RecordingExists
from vmas_ros.record.recover_cli import main as recover_main
from vmas_ros.record.rosbag2 import folder_files

MS = 1_000_000
POSE = "geometry_msgs/msg/PoseStamped"


def _record(recorder: McapRecorder, steps: int, start: int = 0) -> None:
    for i in range(start, start + steps):
        recorder.write("/pose", POSE, None, i * MS, serialized=_pose_bytes(i))


def _metadata(folder: Path) -> dict:
    return yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def test_folder_layout_splits_and_metadata(tmp_path):
    folder = tmp_path / "run"
    with McapRecorder(folder, max_bytes=4000, chunk_size=1024, compression="none") as recorder:
        _record(recorder, 200)
    names = [p.name for p in folder_files(folder)]
    assert names[:3] == ["run_0.mcap", "run_1.mcap", "run_2.mcap"] and len(names) == len(recorder.paths)
    info = _metadata(folder)
    assert info["relative_file_paths"] == names and info["message_count"] == 200
    assert info["starting_time"]["nanoseconds_since_epoch"] == 0 and info["duration"]["nanoseconds"] == 199 * MS
    assert sum(f["message_count"] for f in info["files"]) == 200
    topic = info["topics_with_message_count"][0]
    assert topic["message_count"] == 200 and topic["topic_metadata"]["type"] == POSE
    assert topic["topic_metadata"]["type_description_hash"].startswith("RIHS01_")
    assert topic["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "reliable"
    with Reader(folder) as reader:
        assert [t for _, t, _ in reader.messages()] == [i * MS for i in range(200)]
    assert recorder.describe() == f"{folder}: 200 messages in {len(names)} files, 0.20 s"


def test_existing_bags_are_refused_and_only_bags_are_overwritten(tmp_path):
    folder = tmp_path / "run"
    with McapRecorder(folder, max_bytes=4000, chunk_size=1024) as recorder:
        _record(recorder, 100)
    with pytest.raises(RecordingExists, match=r"run exists \(a folder that is not empty\).*overwrite=True") as caught:
        McapRecorder(folder)
    assert caught.value.path == folder
    with McapRecorder(folder, overwrite=True) as recorder:  # the old splits go with the old metadata
        _record(recorder, 5)
    assert sorted(p.name for p in folder.iterdir()) == ["metadata.yaml", "run_0.mcap"]
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match=r"not part of a bag \(notes.txt\)"):
        McapRecorder(folder, overwrite=True)
    assert (folder / "notes.txt").read_text() == "mine" and (folder / "run_0.mcap").is_file()
    (tmp_path / "plain").write_text("a file")
    with pytest.raises(RecordingExists, match="a file, not a bag folder"):
        McapRecorder(tmp_path / "plain", overwrite=True)


def test_a_vanished_folder_is_reported_at_close(tmp_path):
    folder = tmp_path / "run"
    failures = []
    recorder = McapRecorder(folder, chunk_size=1024, on_failure=failures.append)
    _record(recorder, 50)
    shutil.rmtree(folder)
    recorder.close()
    assert len(failures) == 1 and recorder.failure is failures[0]
    text = str(failures[0])
    assert f"recording to {folder} failed: writing {folder / 'run_0.mcap'}: the file was deleted" in text
    assert "at least 0 of 50 messages are safe" in text
    assert not recorder.write("/pose", POSE, None, 60 * MS, serialized=_pose_bytes(60)), "later writes are dropped"


CHILD = """
import json, resource, sys
resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))
from test.record.bag_helpers import _pose_bytes
from vmas_ros.record import McapRecorder, RecordingFailed
recorder = McapRecorder(sys.argv[1], chunk_size=4096, compression="none")
try:
    for i in range(100_000):
        recorder.write("/pose", "geometry_msgs/msg/PoseStamped", None, i * 1_000_000, serialized=_pose_bytes(i))
except RecordingFailed as failure:
    print(json.dumps({"text": str(failure), "safe": failure.safe, "total": failure.total,
                      "errno": failure.cause.errno, "closed": recorder.closed}))
"""


@pytest.mark.parametrize("name", ["run.mcap", "run"])
def test_a_full_file_raises_one_error_and_the_bag_recovers(tmp_path, name):
    bag = tmp_path / name
    result = subprocess.run([sys.executable, "-c", CHILD, str(bag)], cwd=REPO, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    report = json.loads(result.stdout)
    assert report["errno"] == 27 and report["closed"], report  # EFBIG
    assert "File too large" in report["text"] and f"vmas-ros bag-recover {bag}" in report["text"]
    out = tmp_path / "fixed"
    assert recover_main([str(bag), str(out) + (".mcap" if name.endswith(".mcap") else "")]) == 0
    if name.endswith(".mcap"):
        from rosbags.highlevel import AnyReader

        with AnyReader([Path(str(out) + ".mcap")]) as reader:
            kept = sum(1 for _ in reader.messages())
    else:
        with Reader(out) as reader:
            kept = sum(1 for _ in reader.messages())
        assert _metadata(out)["message_count"] == kept
    assert 0 < report["safe"] <= kept <= report["total"], (report, kept)


def test_bag_recover_rebuilds_a_killed_folder(tmp_path, capsys):
    live, killed = tmp_path / "live", tmp_path / "killed"
    recorder = McapRecorder(live, max_bytes=6000, chunk_size=1024)
    _record(recorder, 300)
    killed.mkdir()
    for path in folder_files(live):  # what a SIGKILL leaves: finished splits, the open one, no metadata
        shutil.copyfile(path, killed / path.name.replace("live", "killed"))
    recorder.close()
    assert not (killed / "metadata.yaml").exists()
    assert recover_main([str(killed)]) == 0
    out = tmp_path / "killed.recovered"
    printed = capsys.readouterr().out
    assert f"into {out} (metadata.yaml rebuilt)" in printed and "recovered up to the damage" in printed
    files = folder_files(killed)
    assert [p.name for p in folder_files(out)] == [p.name for p in files]
    first = out / files[0].name  # complete: linked (or copied) as it is
    assert os.path.samefile(files[0], first) or first.read_bytes() == files[0].read_bytes()
    with Reader(out) as reader:
        times = [t for _, t, _ in reader.messages()]
    assert times == [i * MS for i in range(len(times))] and 200 < len(times) < 300
    assert _metadata(out)["message_count"] == len(times)
    assert recover_main([str(killed)]) == 2 and "exists; pass --force" in capsys.readouterr().err
    assert recover_main([str(killed), "--force"]) == 0
