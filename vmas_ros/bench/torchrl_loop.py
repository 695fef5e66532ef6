"""``vmas-ros bench torchrl``: TorchRL's multi-agent PPO loop, as a whole process, on vmas_ros and on VMAS.

A MARL researcher's first run: TorchRL's ``VmasEnv`` at the size of TorchRL's
multi-agent PPO tutorial (:mod:`vmas_ros.bench.torchrl_loop_side` has the
loop). The vmas_ros side runs it through ``install_as_vmas()``, in the
default mode; the VMAS side on VMAS itself. Each repeat is one fresh process
per side, alternating, timed from start to exit; the rows give the medians,
the collector's and the training's own seconds, and the last iteration's
mean episode reward (both sides should learn alike).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional

__all__ = ["run_torchrl_benchmark", "format_table", "write_results"]

_SIDE_SCRIPT = Path(__file__).with_name("torchrl_loop_side.py")
SIDES = ("vmas_ros", "vmas")


def run_side(side: str, seed: int, config: Optional[dict] = None) -> dict:
    """One fresh process of ``side``: what it printed, plus ``process_s``; RuntimeError with its last lines if
    it fails. ``config`` replaces entries of the loop's settings (``torchrl_loop_side.CONFIG``)."""
    environ = {key: value for key, value in os.environ.items()
               if key not in ("VMAS_ROS_COMPILE", "PYTHONDONTWRITEBYTECODE")}  # the default mode; cached bytecode
    start = time.perf_counter()
    done = subprocess.run([sys.executable, str(_SIDE_SCRIPT), json.dumps({"side": side, "seed": seed, "config": config or {}})],
                          capture_output=True, text=True, env=environ)
    seconds = time.perf_counter() - start
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"the TorchRL loop on {side} exited {done.returncode}: {done.stderr.strip()[-1500:]}")
    return dict(json.loads(lines[-1]), process_s=seconds)


def run_torchrl_benchmark(repeats: int = 3, progress: bool = True) -> List[dict]:
    """One row per side: medians over ``repeats`` processes (seeds 0, 1, ...), the sides alternating."""
    if repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {repeats}")
    from tqdm import tqdm

    runs: Dict[str, List[dict]] = {side: [] for side in SIDES}
    with tqdm(total=repeats * len(SIDES), desc="bench torchrl", disable=not progress) as bar:
        for repeat in range(repeats):
            for side in (SIDES if repeat % 2 == 0 else SIDES[::-1]):
                runs[side].append(run_side(side, seed=repeat))
                bar.update()
    rows = []
    for side, samples in runs.items():
        row = {"side": side, "repeats": repeats}
        for key in ("process_s", "collect_s", "train_s", "last_mean_episode_reward"):
            row[key] = statistics.median(sample[key] for sample in samples)
        row["samples"] = samples
        rows.append(row)
    vmas = next(row for row in rows if row["side"] == "vmas")
    for row in rows:
        row["process_ratio"] = row["process_s"] / vmas["process_s"]
    return rows


def format_table(rows: List[dict]) -> str:
    lines = ["| side | whole process s | / VMAS | collecting s | training s | last mean episode reward |",
             "|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        label = "VMAS 1.5" if row["side"] == "vmas" else "vmas_ros (default mode)"
        lines.append(f"| {label} | {row['process_s']:.1f} | {row['process_ratio']:.2f}x | {row['collect_s']:.1f} | "
                     f"{row['train_s']:.1f} | {row['last_mean_episode_reward']:.2f} |")
    return "\n".join(lines)


def write_results(rows: List[dict], out: str) -> Dict[str, Path]:
    """``torchrl_loop.md`` and ``torchrl_loop.json`` in ``out``."""
    from vmas_ros.bench.report import write_table_and_rows

    return write_table_and_rows(rows, out, "torchrl_loop", format_table(rows))
