"""The report of ``vmas-ros train-suite``: curves CSV, heuristics CSV, Markdown summary and Figure-3-style plots.

Everything is drawn from the runs' per-iteration history (``episode_reward_mean``:
mean return per agent of the episodes that ended in the iteration) and the
heuristic's mean episode return per agent measured with the same episode length
and number of envs, so the horizontal line and the curves share units.

Written to the report folder::

    curves.csv          one row per run and iteration
    heuristics.csv      one row per scenario: the heuristic's return and done fraction
    summary.md          final reward per algorithm and scenario next to the heuristic
    <scenario>.png      one plot per scenario (mean over seeds, min-max band, heuristic line)
    figure3.png         all scenarios in one grid, like the paper's Figure 3
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Dict, List, Sequence

__all__ = ["FINAL_WINDOW", "seed_curves", "final_reward", "draw_scenario", "write_report"]

#: the "final reward" of a run is the mean over its last FINAL_WINDOW iterations (one iteration is noisy)
FINAL_WINDOW = 5
_COLORS = {"cppo": "tab:blue", "mappo": "tab:orange", "ippo": "tab:green", "hetippo": "tab:red"}
_CURVE_COLUMNS = ("scenario", "algorithm", "seed", "iteration", "frames", "episode_reward_mean", "episodes",
                  "step_reward_mean", "seconds")


def _nanmean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return sum(finite) / len(finite) if finite else math.nan


def seed_curves(runs, histories: Dict[str, List[Dict[str, float]]], scenario: str,
                algorithm: str) -> Dict[str, List[float]]:
    """Per iteration over the seeds of one (scenario, algorithm): mean, min and max episode reward."""
    curves = [[float(row["episode_reward_mean"]) for row in histories[run.name]]
              for run in runs if run.scenario == scenario and run.algorithm == algorithm]
    length = max((len(c) for c in curves), default=0)
    result: Dict[str, List[float]] = {"iteration": list(range(1, length + 1)), "mean": [], "min": [], "max": []}
    for i in range(length):
        column = [c[i] for c in curves if i < len(c) and not math.isnan(c[i])]
        result["mean"].append(sum(column) / len(column) if column else math.nan)
        result["min"].append(min(column) if column else math.nan)
        result["max"].append(max(column) if column else math.nan)
    return result


def final_reward(history: List[Dict[str, float]], window: int = FINAL_WINDOW) -> float:
    """Mean episode reward over the run's last ``window`` iterations (NaN iterations, with no ended episode, skipped)."""
    return _nanmean([float(row["episode_reward_mean"]) for row in history[-window:]])


def draw_scenario(axes, runs, histories, scenario: str, algorithms: Sequence[str], heuristic: float) -> None:
    """One algorithm per line (mean over seeds) with its min-max band, and the heuristic as a dashed line."""
    last = 1
    for algorithm in algorithms:
        curve = seed_curves(runs, histories, scenario, algorithm)
        if not curve["iteration"]:
            continue
        last = max(last, curve["iteration"][-1])
        color = _COLORS.get(algorithm)
        axes.plot(curve["iteration"], curve["mean"], label=algorithm.upper() if algorithm != "hetippo" else "HetIPPO",
                  color=color, linewidth=1.6)
        axes.fill_between(curve["iteration"], curve["min"], curve["max"], color=color, alpha=0.2, linewidth=0)
    axes.axhline(heuristic, color="black", linestyle="--", linewidth=1.2, label="heuristic")
    axes.set_xlim(1, max(last, 2))
    axes.set_title(scenario.replace("_", " ").title())
    axes.set_xlabel("training iteration")
    axes.set_ylabel("mean episode reward (per agent)")
    axes.grid(alpha=0.3)


def _config_line(runs) -> str:
    config = runs[0].config
    return (f"{config.iterations} iterations x {config.frames_per_batch} frames ({config.num_envs} envs x "
            f"{config.steps_per_batch} steps, episodes of {config.max_steps} steps), {config.epochs} PPO epochs of "
            f"{config.minibatch_size}-step minibatches, lr {config.lr:g}, gamma {config.gamma:g}, "
            f"lambda {config.lmbda:g}, {config.depth}x{config.num_cells} tanh MLPs")


def _markdown(runs, histories, heuristics, scenarios, algorithms) -> str:
    seeds = sorted({run.seed for run in runs})
    lines = [f"Final mean episode reward per agent (mean of the last {FINAL_WINDOW} iterations; mean over "
             f"seed(s) {', '.join(map(str, seeds))}, min-max across seeds in brackets when there are several). "
             f"Heuristic: same episode length and envs.", "",
             "| scenario | " + " | ".join(a.upper() if a != "hetippo" else "HetIPPO" for a in algorithms)
             + " | heuristic | best |",
             "| --- | " + " | ".join("---:" for _ in algorithms) + " | ---: | --- |"]
    for scenario in scenarios:
        cells, means = [], {}
        for algorithm in algorithms:
            finals = [final_reward(histories[r.name]) for r in runs
                      if r.scenario == scenario and r.algorithm == algorithm]
            means[algorithm] = _nanmean(finals)
            text = f"{means[algorithm]:.3f}"
            if len(finals) > 1:
                text += f" [{min(finals):.3f}, {max(finals):.3f}]"
            cells.append(text)
        heuristic = heuristics[scenario]["mean_return"]
        ranked = sorted((v, a) for a, v in means.items() if not math.isnan(v))
        best = ranked[-1][1] if ranked else ""
        best_text = f"{best}{' (above heuristic)' if ranked and ranked[-1][0] > heuristic else ''}"
        lines.append(f"| `{scenario}` | " + " | ".join(cells) + f" | {heuristic:.3f} | {best_text} |")
    seconds = sum(float(row["seconds"]) for rows in histories.values() for row in rows)
    lines += ["", f"Settings: {_config_line(runs)}.", "",
              f"Training time summed over all runs' iterations: {seconds / 60:.1f} min "
              f"({len(runs)} runs)."]
    return "\n".join(lines) + "\n"


def write_report(report_dir: Path, runs, histories: Dict[str, List[Dict[str, float]]],
                 heuristics: Dict[str, Dict[str, float]], scenarios: Sequence[str],
                 algorithms: Sequence[str]) -> List[Path]:
    """Write every report file (see the module docstring); returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    report_dir.mkdir(parents=True, exist_ok=True)
    paths: List[Path] = []
    curves = report_dir / "curves.csv"
    with curves.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(_CURVE_COLUMNS)
        for run in runs:
            for row in histories[run.name]:
                writer.writerow([run.scenario, run.algorithm, run.seed] + [_fmt(row.get(key, math.nan))
                                                                           for key in _CURVE_COLUMNS[3:]])
    paths.append(curves)
    config = runs[0].config
    heuristics_csv = report_dir / "heuristics.csv"
    with heuristics_csv.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["scenario", "mean_return", "done_fraction", "num_envs", "max_steps", "seeds"])
        for scenario in scenarios:
            h = heuristics[scenario]
            writer.writerow([scenario, _fmt(h["mean_return"]), _fmt(h["done_fraction"]), config.num_envs,
                             config.max_steps, " ".join(str(s) for s in sorted({r.seed for r in runs}))])
    paths.append(heuristics_csv)
    summary = report_dir / "summary.md"
    summary.write_text(_markdown(runs, histories, heuristics, scenarios, algorithms))
    paths.append(summary)
    for scenario in scenarios:
        fig, axes = plt.subplots(figsize=(6, 4))
        draw_scenario(axes, runs, histories, scenario, algorithms, heuristics[scenario]["mean_return"])
        axes.legend(fontsize=8)
        fig.tight_layout()
        paths.append(_save(fig, report_dir / f"{scenario}.png"))
    columns = 2 if len(scenarios) > 1 else 1
    rows = math.ceil(len(scenarios) / columns)
    fig, grid = plt.subplots(rows, columns, figsize=(6 * columns, 4 * rows), squeeze=False)
    for axes, scenario in zip(grid.flat, scenarios):
        draw_scenario(axes, runs, histories, scenario, algorithms, heuristics[scenario]["mean_return"])
    for axes in list(grid.flat)[len(scenarios):]:
        axes.set_visible(False)
    handles, labels = grid.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False)
    fig.suptitle(f"PPO variants against the heuristic ({config.iterations} iterations x "
                 f"{config.frames_per_batch} frames)")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    paths.append(_save(fig, report_dir / "figure3.png"))
    return paths


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def _fmt(value: Any) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)
