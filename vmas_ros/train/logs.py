"""Per-iteration CSV log and the learning-curve PNG of a training run."""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Dict, List, Sequence, Union

__all__ = ["LOG_COLUMNS", "write_csv", "plot_learning_curve"]

#: CSV columns, in order (one row per iteration)
LOG_COLUMNS = (
    "iteration",             # 1-based
    "frames",                # env interactions so far (num_envs x steps, all iterations)
    "episode_reward_mean",   # mean return (per agent) of the episodes that ended this iteration; nan if none did
    "episodes",              # how many episodes ended this iteration
    "step_reward_mean",      # mean reward per agent and step over the batch (defined even when no episode ended)
    "loss_objective",        # PPO clipped surrogate loss (mean over minibatches)
    "loss_critic",           # value loss
    "loss_entropy",          # entropy loss (-coef x entropy)
    "entropy",               # policy entropy estimate
    "seconds_collect",       # time spent stepping the envs
    "seconds_train",         # time spent in GAE + PPO updates
    "seconds",               # whole iteration
    "frames_per_second",     # frames_per_batch / seconds_collect
)


def write_csv(path: Union[str, Path], rows: Sequence[Dict[str, float]]) -> Path:
    """Rewrite the whole log (cheap, and a resumed run's file stays consistent with its checkpoint)."""
    path = Path(path)
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=LOG_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _fmt(row.get(key, math.nan)) for key in LOG_COLUMNS})
    tmp.replace(path)
    return path


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def plot_learning_curve(path: Union[str, Path], rows: Sequence[Dict[str, float]], title: str) -> Path:
    """Mean episode reward against frames (and mean step reward, which exists every iteration)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames: List[float] = [row["frames"] for row in rows]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    episode = [(f, row["episode_reward_mean"]) for f, row in zip(frames, rows)
               if not math.isnan(row["episode_reward_mean"])]
    if episode:
        top.plot([e[0] for e in episode], [e[1] for e in episode], marker="o", markersize=3)
    top.set_ylabel("mean episode reward\n(per agent)")
    top.set_title(title)
    top.grid(alpha=0.3)
    bottom.plot(frames, [row["step_reward_mean"] for row in rows], color="tab:orange", marker="o", markersize=3)
    bottom.set_ylabel("mean reward per step")
    bottom.set_xlabel("frames (env interactions)")
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
