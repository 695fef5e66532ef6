"""The soak command's short CI versions, and proof that its detectors fire.

A soak that always says "ok" is worse than none, so next to the short real runs
(engine: 200 envs x 2000 steps; node: sim_node as a process for 10 s with a bag,
a Foxglove client and commands) every verdict is made to fail once for real:
a hook that keeps every step's tensor alive (a leak), one that writes a NaN
into an agent's state, and a node asked for more steps per second than this
machine can give.
"""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from vmas_ros.bench.soak import run_engine_soak, write_outputs
from vmas_ros.bench.soak_node import read_bag_counts, run_node_soak

pytestmark = pytest.mark.serial  # its verdicts read the machine's steps per second and memory

REPO = Path(__file__).resolve().parents[2]


def test_short_engine_soak_reports_real_figures(tmp_path: Path) -> None:
    result = run_engine_soak(num_envs=200, steps=2000, sample_every=100, progress=False)
    assert result.ok, result.failures
    assert result.steps_done == 2000 and result.finite_checks == 20
    assert len(result.samples) == 21 and all(s.rss_mb > 50 for s in result.samples)  # a torch process is never tiny
    assert all(s.torch_mb > 0 for s in result.samples)  # the env's state tensors are found
    assert result.steps_per_s > 0 and result.nonfinite_at_step is None
    paths = write_outputs(result, str(tmp_path), "soak_engine")
    rows = list(csv.DictReader(paths["csv"].open()))
    assert [int(r["step"]) for r in rows] == list(range(0, 2001, 100))
    summary = json.loads(paths["json"].read_text())
    assert summary["ok"] is True and summary["n_samples"] == 21
    assert paths["png"].stat().st_size > 1000


def test_engine_soak_detects_a_tensor_leak() -> None:
    kept = []

    def leak(env, step: int) -> None:
        kept.append(torch.ones(4096))  # 16 KiB of tensor kept alive per step

    result = run_engine_soak(num_envs=50, steps=1000, sample_every=50, progress=False, step_hook=leak)
    assert not result.ok
    assert result.torch_growth_mb > 5, result.torch_growth_mb  # ~10 MB between the quarter medians
    assert any("live tensors grew" in f for f in result.failures), result.failures


def test_engine_soak_detects_a_nan_and_stops() -> None:
    def poison(env, step: int) -> None:
        if step == 130:
            env.agents[1].set_pos(torch.tensor([float("nan"), 0.0]), batch_index=3)

    result = run_engine_soak(num_envs=20, steps=1000, sample_every=50, progress=False, step_hook=poison)
    assert not result.ok
    assert result.nonfinite_at_step == 150 and result.steps_done == 150  # found at the first check after it
    assert any("non-finite" in f for f in result.failures)


def test_soak_engine_command_writes_files_and_exit_code(tmp_path: Path) -> None:
    """The command as users run it (through ``python -m``, as cli.py will call ``run``)."""
    proc = subprocess.run(
        [sys.executable, "-m", "vmas_ros.bench.soak", "engine", "--num-envs", "50", "--steps", "300",
         "--sample-every", "30", "--out", str(tmp_path), "--no-progress"],
        cwd=REPO, capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "verdict: ok" in proc.stdout
    assert {p.name for p in tmp_path.iterdir()} >= {"soak_engine.csv", "soak_engine.json", "soak_engine.png"}
    bad = subprocess.run([sys.executable, "-m", "vmas_ros.bench.soak", "engine", "--steps", "10", "--warmup-steps", "10",
                          "--out", str(tmp_path), "--no-progress"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "warm-up" in bad.stderr


def test_short_node_soak_with_recording_foxglove_and_commands(tmp_path: Path) -> None:
    result = run_node_soak(duration_s=10, sample_every_s=1, warmup_s=2, out_dir=str(tmp_path), progress=False)
    assert result.node_exit_code == 0
    assert result.rate_hz == pytest.approx(10.0)  # simple_spread's dt 0.1 s at real time
    assert result.steps_expected >= 70 and result.steps_taken >= 0.5 * result.steps_expected
    assert len(result.samples) >= 8 and all(s.rss_mb > 50 for s in result.samples)
    assert result.bag_readable and result.bag_clock_messages >= result.steps_taken
    counts = read_bag_counts(Path(result.bag_path))  # read back independently here too
    assert counts["/clock"] == result.bag_clock_messages and counts["/agent_0/pose"] > 0
    assert result.commands_sent >= 150 and result.commands_recorded > 0
    assert result.foxglove_messages_received > 0 and result.foxglove_commands_recorded > 0
    assert 0.8 < result.real_time_factor < 1.2


def test_node_soak_detects_missed_steps(tmp_path: Path) -> None:
    """Asked for 20,000 steps/s (about 100x what sim_node manages here), the node must be judged behind."""
    result = run_node_soak(duration_s=6, rate_hz=20_000, sample_every_s=1, warmup_s=1, cmd_rate_hz=5,
                           out_dir=str(tmp_path), progress=False)
    assert result.missed_steps > 0.5 * result.steps_expected
    assert not result.ok and any("missed" in f for f in result.failures), result.failures
