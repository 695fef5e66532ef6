"""``vmas-ros bench randomisation``: what training's randomisation costs a step.

Navigation (4 agents with lidars, the training recipes' task) at ``num_envs``
envs, stepped with randomisation off and with each group of settings on
(commands: latency and lag; observations: position, velocity and lidar noise
and dropout; dynamics: mass and drag scales; all of them), eagerly and with
the compiled step. Each configuration is one env, built once and warmed up
(the compiled ones compile then); the timed blocks of ``steps`` steps
alternate between the configurations, ``repeats`` times, in a rotating
order, and the table gives each one's median ms per step and its cost
against the median of randomisation off in the same mode.
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Dict, List, Sequence

import torch

__all__ = ["CONFIGURATIONS", "DEFAULT_NUM_ENVS", "run_randomisation_benchmark", "format_table", "write_results"]

DEFAULT_NUM_ENVS = 600
DEFAULT_STEPS = 200
WARMUP_STEPS = 20
#: the cost the randomisation may add to a step, at most
GOAL = 0.10
_COMMANDS = {"command_latency": [0.0, 0.1], "actuator_lag": [0.0, 0.15]}
_OBSERVATIONS = {"position_noise": [0.0, 0.01], "velocity_noise": [0.0, 0.03], "lidar_noise": [0.0, 0.01],
                 "lidar_dropout": [0.0, 0.05]}
_DYNAMICS = {"mass_scale": [0.8, 1.25], "drag_scale": [0.8, 1.25]}
#: name -> randomisation settings (the ranges of the navigation recipes)
CONFIGURATIONS: Dict[str, dict] = {"off": {}, "commands": _COMMANDS, "observations": _OBSERVATIONS,
                                   "dynamics": _DYNAMICS, "all": {**_COMMANDS, **_OBSERVATIONS, **_DYNAMICS}}
MODES = ("eager", "compiled")


def _timed_block(env, actions: List[List[torch.Tensor]]) -> float:
    """ms per step over ``actions`` (one list of per-agent tensors per step)."""
    started = time.perf_counter()
    for step in actions:
        env.step(step)
    return 1000 * (time.perf_counter() - started) / len(actions)


def run_randomisation_benchmark(num_envs: int = DEFAULT_NUM_ENVS, steps: int = DEFAULT_STEPS, repeats: int = 5,
                                modes: Sequence[str] = MODES, seed: int = 0, progress: bool = True) -> List[dict]:
    """One row per mode and configuration: median ms per step and the cost against randomisation off."""
    from vmas_ros.envs.make_env import make_env
    from tqdm import tqdm

    if num_envs < 1 or steps < 1 or repeats < 1:
        raise ValueError(f"num_envs, steps and repeats must be >= 1, got {num_envs}, {steps}, {repeats}")
    unknown = [mode for mode in modes if mode not in MODES]
    if unknown or not modes:
        raise ValueError(f"modes must be among {list(MODES)}, got {list(modes)}")
    generator = torch.Generator().manual_seed(seed)
    rows = []
    names = list(CONFIGURATIONS)
    bar = tqdm(total=len(modes) * len(names) * (repeats + 1), desc="bench randomisation", disable=not progress)
    for mode in modes:
        envs = {}
        for name in names:
            envs[name] = make_env("navigation", num_envs=num_envs, seed=seed, continuous_actions=True,
                                  compile_physics=mode == "compiled",
                                  randomisation=CONFIGURATIONS[name] or None)
        n_agents = envs["off"].n_agents
        actions = [[torch.rand(num_envs, 2, generator=generator) * 2 - 1 for _ in range(n_agents)]
                   for _ in range(steps)]
        for name in names:  # the compiled ones compile here
            _timed_block(envs[name], actions[:WARMUP_STEPS])
            bar.update(1)
        samples: Dict[str, List[float]] = {name: [] for name in names}
        for repeat in range(repeats):
            for name in names[repeat % len(names):] + names[:repeat % len(names)]:
                samples[name].append(_timed_block(envs[name], actions))
                bar.update(1)
        off = statistics.median(samples["off"])
        for name in names:
            median = statistics.median(samples[name])
            rows.append({"mode": mode, "configuration": name, "settings": CONFIGURATIONS[name],
                         "num_envs": num_envs, "steps": steps, "repeats": repeats, "ms_per_step": median,
                         "cost": median / off - 1, "samples_ms": samples[name],
                         "compiled": envs[name].world.physics_compiled})
    bar.close()
    return rows


def format_table(rows: List[dict]) -> str:
    lines = ["| mode | randomisation | envs | ms/step | cost against off | goal |", "|---|---|---:|---:|---:|---|"]
    for row in rows:
        goal = "" if row["configuration"] == "off" else ("✓" if row["cost"] < GOAL else "✗") + f" < {GOAL:.0%}"
        lines.append(f"| {row['mode']} | {row['configuration']} | {row['num_envs']:,} | {row['ms_per_step']:.3f} | "
                     f"{row['cost']:+.1%} | {goal} |")
    return "\n".join(lines)


def write_results(rows: List[dict], out: str) -> Dict[str, Path]:
    """``randomisation.md`` and ``randomisation.json`` in ``out``."""
    from vmas_ros.bench.report import write_table_and_rows

    return write_table_and_rows(rows, out, "randomisation", format_table(rows))
