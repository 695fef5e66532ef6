"""sim_node records rosbag2 bag folders, refuses to overwrite a bag, and fails well when the disk fills.

The folder is read by rosbags' folder ``Reader`` (what ``ros2 bag`` also
opens), independently of our writer, and ``metadata.yaml`` is checked against
what each MCAP file holds. The full disk is real: a small tmpfs mounted for
the test where this process may mount one, otherwise a child process whose
file size limit (``RLIMIT_FSIZE``) makes its writes fail with EFBIG.
"""
from __future__ import annotations

import re
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock

from test.ros.conftest import REPO, SimProcess

pytestmark = pytest.mark.ros

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
SMALL_BYTES = 1_000_000  # the small filesystem (or the file size limit)
SAFE = re.compile(r"at least (\d+) of (\d+) messages are safe")


def _per_file_counts(folder: Path) -> dict:
    """file name -> {topic: count}, read file by file with rosbags (not through metadata.yaml)."""
    counts = {}
    for path in sorted(folder.glob("*.mcap")):
        topics: dict = {}
        with AnyReader([path], default_typestore=TYPESTORE) as reader:
            for connection, _, raw in reader.messages():
                reader.deserialize(raw, connection.msgtype)
                topics[connection.topic] = topics.get(connection.topic, 0) + 1
        counts[path.name] = topics
    return counts


def _check_folder(folder: Path) -> int:
    """The bag folder's metadata.yaml says what its files hold, and rosbags' Reader reads all of it."""
    info = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    per_file = _per_file_counts(folder)
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert sorted(info["relative_file_paths"]) == sorted(per_file), (info["relative_file_paths"], per_file)
    for entry in info["files"]:
        assert entry["message_count"] == sum(per_file[entry["path"]].values()), entry
    totals: dict = {}
    for topics in per_file.values():
        for topic, n in topics.items():
            totals[topic] = totals.get(topic, 0) + n
    listed = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert listed == totals
    assert info["message_count"] == sum(totals.values())
    with Reader(folder) as reader:
        assert reader.message_count == info["message_count"]
        read = sum(1 for _ in reader.messages())
        assert {c.topic for c in reader.connections} == set(totals)
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert read == info["message_count"]
    assert all(qos[t] for t in totals), "every topic carries its offered QoS"
    return read


def test_bag_folder_reads_back_and_is_not_overwritten(ros, sim_node, sim_process, tmp_path):
    folder = tmp_path / "run"
    sim = sim_node(record_path=str(folder), record_max_mb=1.0, real_time_factor=0.0, lidar_rays=8)
    clock = ros.collect(Clock, "/clock")
    clock.wait_for(300, timeout=30.0)
    assert sim.stop() == 0
    files = sorted(p.name for p in folder.iterdir())
    assert "metadata.yaml" in files and "run_0.mcap" in files and "run_1.mcap" in files, files
    total = _check_folder(folder)
    closed = [line for line in sim.stderr().splitlines() if "bag closed:" in line]
    assert len(closed) == 1 and f"{folder}: {total} messages in " in closed[0], sim.describe()

    again = sim_process(record_path=str(folder))
    assert again.wait(60) == 2
    assert f"record_path: {folder} exists" in again.stderr() and "record_overwrite:=true" in again.stderr()
    assert _check_folder(folder) == total, "a refused start leaves the bag as it was"

    replaced = sim_node(record_path=str(folder), record_overwrite=True, real_time_factor=0.0, lidar_rays=8)
    clock.clear()
    clock.wait_for(5, timeout=30.0)  # recording: the first state is published after the bag is opened
    assert replaced.stop() == 0
    assert sorted(p.name for p in folder.iterdir()) == ["metadata.yaml", "run_0.mcap"], "the old splits are gone"
    assert _check_folder(folder) > 0


# ------------------------------------------------------------------ disk full
@pytest.fixture
def small_disk(tmp_path):
    """(directory with about SMALL_BYTES of room, preexec for the node): a tmpfs where mounting works,
    else a plain directory and a file size limit for the child."""
    mount = tmp_path / "small"
    mount.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={SMALL_BYTES}", "tmpfs", str(mount)],
                             capture_output=True).returncode == 0 if shutil.which("mount") else False

    def limit_file_size() -> None:  # Python ignores SIGXFSZ, so a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (SMALL_BYTES, SMALL_BYTES))

    try:
        reason = "No space left on device" if mounted else "File too large"
        yield mount, (None if mounted else limit_file_size), reason
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(mount)], capture_output=True)


class LimitedSim(SimProcess):
    def __init__(self, *args, preexec=None, **kwargs) -> None:
        self.preexec = preexec
        super().__init__(*args, **kwargs)


def _recover(bag: Path, out: Path) -> Path:
    result = subprocess.run([sys.executable, "-m", "vmas_ros.record.recover_cli", str(bag), str(out)],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return out


@pytest.mark.parametrize("layout, on_error", [("folder", "continue"), ("file", "stop")])
def test_full_disk_gives_one_line_and_a_readable_bag(ros, sim_log_dir, small_disk, tmp_path, layout, on_error):
    directory, preexec, reason = small_disk
    bag = directory / ("run" if layout == "folder" else "run.mcap")
    params = dict(record_path=str(bag), record_on_error=on_error, real_time_factor=0.0, lidar_rays=32)
    sim = LimitedSim(ros, params, sim_log_dir, f"disk_full_{layout}", preexec=preexec)
    try:
        failed = ros.spin_until(lambda: [l for l in sim.stderr().splitlines() if "failed: writing" in l],
                                60.0, "the recording to fail")
        if on_error == "continue":
            clock = ros.collect(Clock, "/clock")
            clock.wait_for(50, timeout=20.0)  # still simulating and publishing
            assert sim.alive()
            assert sim.stop() == 0
        else:
            assert sim.wait(30) == 4, sim.describe()
    finally:
        sim.kill()
    err = sim.stderr()
    assert "Traceback" not in err, err
    lines = [l for l in err.splitlines() if "failed: writing" in l]
    assert len(lines) == 1 and lines == failed[:1], err
    line = lines[0]
    assert f"recording to {bag} failed" in line and reason in line and "bag-recover" in line, line
    expected = "goes on without recording" if on_error == "continue" else "(record_on_error: stop)"
    assert expected in line, line
    safe, total = map(int, SAFE.search(line).groups())
    recovered = _recover(bag, tmp_path / ("recovered" if layout == "folder" else "recovered.mcap"))
    if layout == "folder":
        kept = _check_folder(recovered)
    else:
        with AnyReader([recovered], default_typestore=TYPESTORE) as reader:
            kept = sum(1 for _ in reader.messages())
    assert 0 < safe <= kept <= total, (safe, kept, total)
