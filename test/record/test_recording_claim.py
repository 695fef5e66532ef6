"""One recorder per path: a second recorder on a live recording's path is refused, naming the holder."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from vmas_ros.record import McapRecorder, RecordingInUse
from vmas_ros.record.claim import lock_path_of


@pytest.mark.parametrize("name", ["bag.mcap", "bag_folder"])
def test_a_second_recorder_on_a_live_path_is_refused(tmp_path, name):
    path = tmp_path / name
    first = McapRecorder(path)
    try:
        for overwrite in (False, True):  # overwrite must not delete a live recording either
            with pytest.raises(RecordingInUse, match=f"is being recorded by pid {os.getpid()} ") as refused:
                McapRecorder(path, overwrite=overwrite)
            assert refused.value.path == path
        assert first.paths and all(p.exists() for p in first.paths)
    finally:
        first.close()
    McapRecorder(path, overwrite=True).close()  # free again once closed
    assert not lock_path_of(path).exists()


def test_another_process_holding_the_path_is_named_and_a_killed_one_holds_nothing(tmp_path):
    path = tmp_path / "bag.mcap"
    holder = textwrap.dedent(f"""
        import sys, time
        from vmas_ros.record import McapRecorder
        recorder = McapRecorder({str(path)!r})
        print("recording", flush=True)
        time.sleep(60)
    """)
    process = subprocess.Popen([sys.executable, "-c", holder, "--label", "holder_one"], stdout=subprocess.PIPE,
                               text=True)
    try:
        assert process.stdout.readline().strip() == "recording"
        with pytest.raises(RecordingInUse, match=rf"pid {process.pid} \(.*--label holder_one\)"):
            McapRecorder(path, overwrite=True)
    finally:
        process.kill()
        process.wait()
    McapRecorder(path, overwrite=True).close()  # the kernel dropped the killed holder's lock

