"""``vmas-ros bench torchrl``: TorchRL's multi-agent PPO loop through ``install_as_vmas()``, as a process.

The full tutorial-size comparison takes minutes per side and is run by hand
(docs/bench/default_mode.md has the command); here one short loop runs for real.
"""
from __future__ import annotations

import math

import pytest

from vmas_ros.bench import torchrl_loop

SMALL = {"frames_per_batch": 200, "max_steps": 20, "n_iters": 2, "num_epochs": 1, "minibatch_size": 100}


def test_a_short_loop_runs_on_vmas_ros_through_torchrls_vmas_env():
    run = torchrl_loop.run_side("vmas_ros", seed=0, config=SMALL)
    assert run["side"] == "vmas_ros" and run["collect_s"] > 0 and run["train_s"] > 0
    assert run["process_s"] >= run["in_process_s"] > run["collect_s"]
    assert math.isfinite(run["last_mean_episode_reward"])


def test_a_failing_loop_names_the_side_and_the_cause():
    with pytest.raises(RuntimeError, match="(?s)on vmas_ros exited 1.*unknown loop settings \\['lr_typo'\\]"):
        torchrl_loop.run_side("vmas_ros", seed=0, config={"lr_typo": 1})


def test_the_table_gives_the_ratio_to_vmas():
    rows = [{"side": side, "process_s": s, "collect_s": 1.0, "train_s": 2.0, "last_mean_episode_reward": 2.5,
             "process_ratio": s / 30.0} for side, s in (("vmas_ros", 27.0), ("vmas", 30.0))]
    table = torchrl_loop.format_table(rows)
    assert "| vmas_ros (default mode) | 27.0 | 0.90x |" in table and "| VMAS 1.5 | 30.0 | 1.00x |" in table
