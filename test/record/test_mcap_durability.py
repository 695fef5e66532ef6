"""McapRecorder's durability: flushes, deferred signals, SIGKILL and SIGTERM, and recovery.

A killed recorder loses at most its open chunk, and ``recover`` rebuilds a
finished bag from the rest (a prefix of the messages, nothing invented); a
SIGTERM whose handler calls ``sys.exit`` leaves a finished bag through the
``atexit`` close. Recorders run in child processes where a signal is sent.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest
from mcap.reader import make_reader

from test.record.bag_helpers import (MS, REPO, _pose_bytes, _read_rosbags, _recovered_xs, _summary,
                                     read_ros2_messages)
from vmas_ros.record import McapRecorder, recover


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
