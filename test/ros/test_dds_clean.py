"""Fast DDS shared memory that a killed process left half made no longer hangs the next node.

A process killed while it sets up one of Fast DDS's shared-memory ports leaves
a file under /dev/shm whose state word says "not ready" for good; every later
participant that probes that port waits for it forever, inside Fast DDS. The
segments here are made the way such a kill leaves them: a file of a port's
size whose first four bytes are 0 (or 1).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

import test.ros.conftest as ros_conftest
from test.ros.conftest import REPO, SimProcess
from vmas_ros.ros import lifecycle
from vmas_ros.rostools.dds_clean import SHM_DIR, remove_stuck_segments, stuck_segments

pytestmark = pytest.mark.ros

PORT_BYTES = 52400  # the size Fast DDS gives a port segment
STARTED = "sim_node: scenario simple_spread"


def _segment(path: Path, state: int, age_s: float = 60.0, size: int = PORT_BYTES) -> Path:
    path.write_bytes(state.to_bytes(4, "little")[:size] + bytes(max(0, size - 4)))
    then = time.time() - age_s
    os.utime(path, (then, then))
    return path


def test_only_old_unready_segments_are_stuck(tmp_path):
    stuck = [_segment(tmp_path / "fastrtps_port7003", 0), _segment(tmp_path / "fastrtps_port7004", 1),
             _segment(tmp_path / "fastrtps_0123456789abcdef", 0), _segment(tmp_path / "fastrtps_port7006", 0, size=0)]
    kept = [_segment(tmp_path / "fastrtps_port7000", 2), _segment(tmp_path / "fastrtps_port7001", 3),
            _segment(tmp_path / "fastrtps_port7002", 0, age_s=0.0),  # being set up right now
            _segment(tmp_path / "fastrtps_port7000_el", 0, size=0), _segment(tmp_path / "other_file", 0)]
    assert stuck_segments(tmp_path) == sorted(stuck)
    assert remove_stuck_segments(tmp_path) == sorted(stuck)
    assert sorted(tmp_path.iterdir()) == sorted(kept)
    assert stuck_segments(tmp_path / "missing") == []
    with pytest.raises(ValueError, match="min_age_s must be >= 0 seconds, got -1"):
        stuck_segments(tmp_path, min_age_s=-1)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vmas_ros.cli", "dds-clean", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


def test_dds_clean_command(tmp_path, capsys):
    stuck = _segment(tmp_path / "fastrtps_port7003", 0)
    ready = _segment(tmp_path / "fastrtps_port7000", 2)
    dry = _cli("--dir", str(tmp_path), "--dry-run")  # as a user runs it
    assert dry.returncode == 0 and f"would remove {stuck}" in dry.stdout and stuck.exists(), dry
    bad = _cli("--dir", str(tmp_path), "--min-age", "-1")
    assert bad.returncode == 2 and "--min-age must be >= 0 seconds, got -1.0" in bad.stderr, bad
    from vmas_ros.cli import main  # the rest in this process: the same entry point, without a new interpreter

    assert main(["dds-clean", "--dir", str(tmp_path)]) == 0
    assert f"removed {stuck}" in capsys.readouterr().out
    assert not stuck.exists() and ready.exists()
    assert main(["dds-clean", "--dir", str(tmp_path)]) == 0
    assert capsys.readouterr().out.strip() == f"no stuck Fast DDS segments under {tmp_path}"


def test_a_slow_start_names_the_stuck_segment(monkeypatch, capsys, tmp_path):
    stuck = tmp_path / "fastrtps_port7003"
    monkeypatch.setattr(lifecycle, "stuck_segments", lambda: [stuck])
    lifecycle._warn_if_dds_stuck("sim_node")
    err = capsys.readouterr().err
    assert f"sim_node: still starting after {lifecycle.STARTUP_DDS_CHECK_S:g} s, and {stuck}" in err
    assert "vmas-ros dds-clean" in err
    monkeypatch.setattr(lifecycle, "stuck_segments", lambda: [])
    lifecycle._warn_if_dds_stuck("sim_node")
    assert capsys.readouterr().err == "", "nothing to say when nothing is stuck"


def _ports_in_use() -> set:
    """Port numbers whose segment (or its ``_el`` lock file) some process has open or mapped."""
    used = set()
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            names = [os.readlink(fd) for fd in (proc / "fd").iterdir()] + [(proc / "maps").read_text()]
        except OSError:  # gone meanwhile, or not ours to read
            continue
        used.update(int(port) for name in names for port in re.findall(r"fastrtps_port(\d+)", name))
    return used


@pytest.mark.skipif(not SHM_DIR.is_dir(), reason="Fast DDS keeps no shared memory here (no /dev/shm)")
@pytest.mark.serial  # it plants stuck segments on the ports every participant on the machine probes
def test_sim_node_starts_past_stuck_ports(sim_log_dir, monkeypatch):
    """Stuck segments on every port no process uses, so a new participant probes one whatever it
    picks: the node removes them and starts (without that it would wait forever). No participant
    runs in this process meanwhile: it would open ports of its own while they are planted."""
    monkeypatch.setattr(ros_conftest, "remove_stuck_segments", lambda: [])  # the node must do it itself
    used = _ports_in_use()
    planted = [_segment(SHM_DIR / f"fastrtps_port{port}", 0) for port in range(7000, 7032) if port not in used]
    assert len(planted) >= 16, used
    process = SimProcess(None, dict(real_time_factor=0.0), sim_log_dir, "past_stuck_ports")
    try:
        end = time.monotonic() + 30.0
        while STARTED not in process.stderr() and process.alive() and time.monotonic() < end:
            time.sleep(0.1)
        started = STARTED in process.stderr()  # logged once its ROS node (and DDS participant) exists
        code = process.stop()
    finally:
        process.kill()
        for path in planted:
            path.unlink(missing_ok=True)
    assert started and code == 0, process.describe()
    removed = [line for line in process.stderr().splitlines() if "Fast DDS shared memory that a killed" in line]
    assert removed == [f"sim_node: removed {p}, Fast DDS shared memory that a killed process left half made "
                       "(it would have made this node wait forever)" for p in planted], process.describe()
