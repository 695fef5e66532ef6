"""Signals at any moment leave a finished bag; SIGKILL leaves one that bag-recover repairs.

Real sim_node processes record to MCAP and get SIGINT or SIGTERM at four
moments: during the imports (before the node exists; once the interpreter has
started and the entry point installed its handler), as soon as the bag file
appears (the node is being built, before its first step), right after the
first message reaches a subscriber, and mid-run at a random delay while the
node steps as fast as it can (so that the signal most likely lands inside a
write). Each stop must exit with code 0 and no traceback and leave a bag that
rosbags reads completely, with a summary and footer, made of whole steps; the
import case must leave no file or a finished one (test_faults_early_signals.py
checks that case in detail). All processes (and the SIGKILL one) run at once, each in
its own namespace, to keep the module short.

SIGKILL cannot be handled: the bag keeps every chunk already written, and
``python -m vmas_ros.record.recover_cli`` (``vmas-ros bag-recover``) must
rebuild all of it but the chunk being filled.
"""
from __future__ import annotations

import random
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional

import pytest
from geometry_msgs.msg import PoseArray

from test.ros.conftest import stamp_ns
from test.ros.fault_tools import (TYPESTORE, FaultProcess, assert_whole_steps, catches_sigterm, is_finished,
                                  read_finished, recover_with_cli, sweep)

pytestmark = pytest.mark.ros

DT_NS = 100_000_000  # simple_spread's dt
CHUNK_BYTES = 1024 * 1024  # McapRecorder's default chunk_size, as sim_node uses it
RECORD_OVERHEAD = 31  # bytes of an MCAP message record around its data (opcode, length, channel, sequence, times)
MOMENTS = ("import", "startup", "first_message", "mid_run")
SIGNALS = {"sigint": signal.SIGINT, "sigterm": signal.SIGTERM}
KILLED = "sigkill.mcap"
#: the killed node runs unpaced until this step: at about 5.3 kB of messages per step, 2 chunks of 1 MiB
KILL_AFTER_STEPS = 450


@dataclass
class Run:
    """One sim_node process stopped by a signal at one moment, and what it left."""

    label: str
    sig: int
    moment: str
    delay: float = 0.0  # mid_run: seconds after the first message; import: seconds after the launch
    process: Optional[FaultProcess] = None
    bag: Optional[Path] = None
    signalled_after: Optional[float] = None  # seconds from launch to the signal
    seen_steps: int = 0  # the newest step a subscriber had received when the signal was sent
    returncode: Optional[int] = None

    def describe(self) -> str:
        return (f"{self.label}: signal {self.sig} at {self.moment} ({self.signalled_after:.2f} s after launch, "
                f"delay {self.delay:.2f} s), rc {self.returncode}\n{self.process.describe()}")


@pytest.fixture(scope="module")
def bag_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fault_signal_bags")


def _run_wave(ros, runs: List[Run], bag_dir: Path, log_dir: Path) -> None:
    """Start every run's process at once, signal each at its moment, wait for all exits."""
    collectors, started = {}, {}
    for run in runs:
        run.bag = bag_dir / f"{run.label}.mcap"
        collectors[run.label] = ros.collect(PoseArray, f"/{run.label}/agents/poses")
        unpaced = run.moment in ("mid_run", "kill")
        params = dict(record_path=str(run.bag), real_time_factor=0.0 if unpaced else 1.0)
        run.process = FaultProcess(ros, params, log_dir, run.label)
        started[run.label] = time.monotonic()
    first_seen: Dict[str, float] = {}
    pending = list(runs)
    deadline = time.monotonic() + 60.0
    while pending:
        assert time.monotonic() < deadline, "signal moments not reached: " + "; ".join(r.describe() for r in pending)
        ros.spin_for(0.002)
        now = time.monotonic()
        for run in list(pending):
            if len(collectors[run.label]) and run.label not in first_seen:
                first_seen[run.label] = now
            due = {
                "import": now - started[run.label] >= run.delay and catches_sigterm(run.process.proc.pid),
                "startup": run.bag.exists(),
                "first_message": run.label in first_seen,
                "mid_run": run.label in first_seen and now - first_seen[run.label] >= run.delay,
                "kill": len(collectors[run.label])
                and stamp_ns(collectors[run.label].latest.header.stamp) >= KILL_AFTER_STEPS * DT_NS,
            }[run.moment]
            if due and len(collectors[run.label]):
                run.seen_steps = stamp_ns(collectors[run.label].latest.header.stamp) // DT_NS
            if due or not run.process.alive():
                run.process.send(run.sig)
                run.signalled_after = now - started[run.label]
                pending.remove(run)
    for run in runs:
        try:
            run.returncode = run.process.wait(30.0)
        finally:
            run.process.kill()
            collectors[run.label].destroy()


@pytest.fixture(scope="module")
def signal_runs(ros, bag_dir, sim_log_dir) -> Dict[str, Run]:
    """All runs at once (nine processes): start-up is most of their cost, and it overlaps."""
    rng = random.Random()
    wave = [Run(f"{name}_{moment}", sig, moment,
                delay=0.3 if moment == "import" else rng.uniform(0.05, 1.5) if moment == "mid_run" else 0.0)
            for name, sig in SIGNALS.items() for moment in MOMENTS]
    wave.append(Run("sigkill", signal.SIGKILL, "kill"))
    _run_wave(ros, wave, bag_dir, sim_log_dir)
    return {run.label: run for run in wave}


@pytest.mark.parametrize("label", [f"{s}_{m}" for s in SIGNALS for m in MOMENTS])
def test_signal_leaves_a_finished_bag(signal_runs, label):
    run = signal_runs[label]
    if run.moment == "import":
        # before rclpy and the node exist, the entry point's guard (vmas_ros/ros/signal_guard.py) ends the
        # process with exit 0 and one line; no bag, or (had the imports been quick) a finished one
        assert run.returncode == 0, run.describe()
        assert "Traceback" not in run.process.stderr(), run.describe()
        if run.bag.exists():
            read_finished(run.bag)
        return
    assert run.returncode == 0, run.describe()
    assert run.bag.exists(), f"no bag: {run.describe()}"
    bag = read_finished(run.bag)
    assert_whole_steps(bag, DT_NS, namespace=f"/{run.label}")
    # every step a subscriber had received is in the bag, except perhaps the one in flight: the node
    # publishes a step before it records it, and the signal may end it in between
    assert len(bag.steps()) >= run.seen_steps, f"{len(bag.steps())} steps recorded: {run.describe()}"
    if run.moment == "mid_run":
        assert len(bag.steps()) >= 3, f"{len(bag.steps())} steps recorded: {run.describe()}"
    assert "Traceback" not in run.process.stderr(), run.describe()


def test_sigkill_then_bag_recover_keeps_all_but_the_last_chunk(signal_runs, bag_dir):
    run = signal_runs["sigkill"]
    bag, seen_steps = run.bag, run.seen_steps
    assert run.returncode == -signal.SIGKILL, run.describe()
    assert not is_finished(bag), "a killed recorder cannot have written its footer"
    with pytest.raises(Exception):
        read_finished(bag)  # the independent reader refuses the raw file

    out = bag_dir / "sigkill.recovered.mcap"
    report = recover_with_cli(bag, out)
    recovered = read_finished(out)
    assert report["messages"] == recovered.total and report["complete"] is False, report
    assert report["topics"] == {t: len(m) for t, m in recovered.messages.items()}, report

    steps = recovered.steps()
    assert steps == [k * DT_NS for k in range(len(steps))], "the recovered steps are the first ones, without gaps"
    # what the recorder held per step (message records, uncompressed): how many steps one chunk holds
    per_step = sum(len(TYPESTORE.serialize_cdr(m, m.__msgtype__)) + RECORD_OVERHEAD
                   for ms in recovered.messages.values() for _, m in ms) / len(steps)
    steps_per_chunk = CHUNK_BYTES / per_step
    lost = seen_steps + 1 - len(steps)  # steps 0..seen_steps were published, so executed, before the kill
    print(f"\nSIGKILL after >= {seen_steps + 1} steps: recovered {len(steps)} steps ({recovered.total} messages, "
          f"{report['chunks']} chunks, {report['bytes_used']} of {report['bytes_total']} bytes); "
          f"{per_step:.0f} B per step, {steps_per_chunk:.0f} steps per chunk; {lost} steps lost")
    assert report["chunks"] >= 2, report
    assert lost <= steps_per_chunk + 2, (
        f"lost {lost} steps, more than one chunk ({steps_per_chunk:.0f} steps) of the {seen_steps} published")


def test_no_corrupted_file_left(signal_runs, bag_dir):
    """Every file the tests above produced is a finished bag, or the SIGKILL one, which is recoverable."""
    verdicts = sweep(bag_dir, killed=[KILLED], min_files=len(SIGNALS) * (len(MOMENTS) - 1) + 2)
    print("\n" + "\n".join(f"{name}: {verdict}" for name, verdict in verdicts.items()))
