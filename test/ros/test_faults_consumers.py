"""Consumers cannot stall sim_node, and a restart with the same seed replays the same run.

Stalls: sim_node steps at ``rate_hz`` 50 while other processes subscribe
(reliable, depth 10) to its poses, odometry and scans: one that sleeps 0.5 s
in every callback, one that is frozen outright (SIGSTOP: not even its DDS
threads run) and one that disappears without a goodbye (SIGKILL). The steps
the node advances in each window (from the stamps a separate, fast
subscriber receives) must stay near the rate: a publisher that waited for a
consumer would fall to a few steps per second.

Reproducibility: two sim_node processes with the same seed, ``control:
heuristic`` and no commands, unpaced, record bags; every message of every
step they both recorded must be identical, field for field and float for float
(the CDR bytes are not: the serialiser leaves alignment padding uninitialised), and their first poses
must be the state ``make_env(seed=...)`` resets to.
"""
from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import struct
import sys
import time
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray

import vmas_ros
from test.ros.conftest import REPO, sim_env, stamp_ns
from test.ros.fault_tools import FaultProcess, read_finished, sweep

pytestmark = pytest.mark.ros

DT_NS = 100_000_000
RATE_HZ = 50.0
WINDOW_S = 2.0
MIN_FRACTION = 0.6  # of RATE_HZ * WINDOW_S steps; a stalled publisher manages a few per second
SEED = 7


def _subscriber(sleep: float, topics: List[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "test.ros.slow_subscriber", str(sleep), *topics],
                            cwd=REPO, env=sim_env(), stdout=open(log, "wb"), stderr=subprocess.STDOUT)


def _received(log: Path) -> int:
    counts = [int(line.split()[1]) for line in log.read_text().splitlines() if line.startswith("received ")]
    return counts[-1] if counts else 0


def _steps_in_window(ros, poses, seconds: float) -> Tuple[int, float]:
    """Steps the node advanced during ``seconds`` of wall time, seen through a fast subscriber."""
    ros.spin_for(0.2)
    start_stamp, start = stamp_ns(poses.latest.header.stamp), time.monotonic()
    ros.spin_for(seconds)
    ros.spin_for(0.1)
    return (stamp_ns(poses.latest.header.stamp) - start_stamp) // DT_NS, time.monotonic() - start


@pytest.fixture(scope="module")
def bag_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fault_consumer_bags")


def test_slow_frozen_and_vanished_consumers_do_not_stall_the_loop(ros, sim_log_dir, bag_dir):
    ns = "/consumers"
    topics = [f"{ns}/agents/poses", f"{ns}/agent_0/odom", f"{ns}/agent_0/scan"]
    poses = ros.collect(PoseArray, topics[0], depth=10)
    sim = FaultProcess(ros, dict(rate_hz=RATE_HZ, record_path=str(bag_dir / "consumers.mcap")), sim_log_dir, "consumers")
    slow_log, frozen_log, gone_log = (sim_log_dir / f"{n}_subscriber.log" for n in ("slow", "frozen", "gone"))
    subscribers = [_subscriber(0.5, topics, slow_log), _subscriber(0.0, topics, frozen_log),
                   _subscriber(0.0, topics, gone_log)]
    slow, frozen, gone = subscribers
    expected = RATE_HZ * WINDOW_S
    windows: Dict[str, Tuple[int, float]] = {}
    try:
        sim.wait_ready()
        poses.wait_for(1, 20)
        ros.spin_until(lambda: all(_received(log) > 0 for log in (slow_log, frozen_log, gone_log)), 30,
                       "every consumer process to receive messages")
        windows["slow + frozen-to-be + vanishing attached"] = _steps_in_window(ros, poses, WINDOW_S)
        os.kill(frozen.pid, signal.SIGSTOP)
        windows["one consumer frozen (SIGSTOP)"] = _steps_in_window(ros, poses, WINDOW_S)
        gone.kill()
        gone.wait(10)
        windows["one consumer vanished (SIGKILL), one frozen"] = _steps_in_window(ros, poses, WINDOW_S)
        slow_count = _received(slow_log)
        assert sim.alive(), sim.describe()
        assert sim.stop(signal.SIGINT) == 0, sim.describe()
    finally:
        for process in subscribers:
            if process.poll() is None:
                os.kill(process.pid, signal.SIGCONT)
                process.kill()
                process.wait(10)
        sim.kill()
        poses.destroy()
    report = "; ".join(f"{name}: {steps} steps in {wall:.2f} s" for name, (steps, wall) in windows.items())
    print(f"\nrate_hz {RATE_HZ}: {report}; the slow consumer took in {slow_count} messages")
    for name, (steps, wall) in windows.items():
        assert steps >= MIN_FRACTION * RATE_HZ * wall, f"{name}: {steps} steps in {wall:.2f} s ({report})"
    # the slow one was attached and slow: it got messages, far fewer than the 3 topics x steps published
    total_steps = sum(steps for steps, _ in windows.values())
    assert 0 < slow_count < 3 * total_steps / 4, (slow_count, total_steps)
    read_finished(bag_dir / "consumers.mcap")


def _values(value) -> tuple:
    """A rosbags message as nested tuples of plain values, compared exactly (floats bit for bit)."""
    if isinstance(value, np.ndarray):
        return ("array", value.dtype.str, value.tobytes())
    if isinstance(value, (list, tuple)):
        return tuple(_values(v) for v in value)
    if dataclasses.is_dataclass(value):
        return tuple((f.name, _values(getattr(value, f.name))) for f in dataclasses.fields(value))
    return (value,) if not isinstance(value, float) else ("float", struct.pack("<d", value))


def _step_records(path: Path, namespace: str) -> Dict[int, Dict[str, tuple]]:
    """log time -> {topic without the namespace: the message's values} of a finished bag.

    Values, not CDR bytes: the alignment padding in CDR is not initialised by the
    serialiser, so two runs' bytes differ where no field lives.
    """
    steps: Dict[int, Dict[str, tuple]] = {}
    for topic, messages in read_finished(path).messages.items():
        for log_time, message in messages:
            steps.setdefault(log_time, {})[topic.removeprefix(namespace)] = _values(message)
    return steps


def test_restart_with_the_same_seed_replays_the_same_run(ros, sim_log_dir, bag_dir):
    runs = []
    for label in ("replay_a", "replay_b"):
        bag = bag_dir / f"{label}.mcap"
        # the same frame names in both (by default each namespace prefixes its own)
        runs.append((label, bag, FaultProcess(ros, dict(seed=SEED, control="heuristic", real_time_factor=0.0,
                                                        num_envs=2, record_path=str(bag), frame_prefix=""),
                                              sim_log_dir, label)))
    try:
        for label, _, process in runs:
            process.wait_ready()
        ros.spin_for(1.5)
        for _, _, process in runs:
            assert process.stop(signal.SIGINT) == 0, process.describe()
    finally:
        for _, _, process in runs:
            process.kill()
    (label_a, bag_a, _), (label_b, bag_b, _) = runs
    a, b = _step_records(bag_a, f"/{label_a}"), _step_records(bag_b, f"/{label_b}")
    common = sorted(set(a) & set(b))
    assert len(common) >= 50 and common == [k * DT_NS for k in range(len(common))], len(common)
    for t in common[:-1]:  # the last common step may be the one a run was stopped in
        assert a[t] == b[t], f"the runs differ at t={t / 1e9:.1f} s: " + ", ".join(
            k for k in sorted(set(a[t]) | set(b[t])) if a[t].get(k) != b[t].get(k))
    moved = read_finished(bag_a).messages[f"/{label_a}/agents/poses"]
    first, last = moved[0][1].poses, moved[len(common) - 2][1].poses
    assert any(abs(p.position.x - q.position.x) > 0.05 for p, q in zip(first, last)), "the heuristic moved no agent"

    # the seed, not luck, makes them equal: the first poses are make_env(seed)'s reset, and another seed differs
    def reset_positions(seed: int) -> List[float]:
        env = vmas_ros.make_env("simple_spread", num_envs=2, seed=seed)
        env.reset()
        return [float(v) for agent in env.agents for v in agent.state.pos[0]]

    recorded = [v for p in first for v in (p.position.x, p.position.y)]
    assert recorded == pytest.approx(reset_positions(SEED), abs=1e-6)
    assert recorded != pytest.approx(reset_positions(SEED + 1), abs=1e-3)
    print(f"\nseed {SEED}: {len(common)} steps recorded by both runs, every field identical")


def test_no_corrupted_file_left(bag_dir):
    verdicts = sweep(bag_dir, min_files=3)
    print("\n" + "\n".join(f"{name}: {verdict}" for name, verdict in verdicts.items()))
