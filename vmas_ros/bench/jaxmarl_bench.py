"""``vmas-ros bench jaxmarl``: simple_spread's step time against JaxMARL's, in the same run.

JaxMARL pins its own JAX, so it lives in an environment of its own: its
interpreter is given with ``--jaxmarl-python`` (or ``VMAS_ROS_JAXMARL_PYTHON``),
for example one made with ``python -m venv /opt/jaxmarl && /opt/jaxmarl/bin/pip
install jaxmarl``. Each repeat runs one fresh process per side, alternating:
JaxMARL's (:mod:`vmas_ros.bench.jaxmarl_side`) and vmas_ros's in the default
mode (``VMAS_ROS_COMPILE`` removed from its environment), which steps on
through the default mode's switch to the compiled step before it is timed,
as a long run would. Both time the same number of steps with continuous
actions drawn beforehand; the table gives each side's median and the ratio
JaxMARL / vmas_ros (above 1: vmas_ros is faster).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence

__all__ = ["DEFAULT_NUM_ENVS", "jaxmarl_python", "run_jaxmarl_benchmark", "format_table", "write_results"]

DEFAULT_NUM_ENVS = (1, 30_000)
DEFAULT_STEPS = 2_000
#: untimed steps after the warm-up (JaxMARL: its jit compile; vmas_ros: after its switch)
WARMUP_STEPS = 200
_SIDE_SCRIPT = Path(__file__).with_name("jaxmarl_side.py")

_VMAS_ROS_SIDE = r"""
import json, sys, time
cfg = json.loads(sys.argv[1])
import torch
from vmas_ros import make_env
n, steps = cfg["num_envs"], cfg["steps"]
env = make_env("simple_spread", num_envs=n, device="cpu", continuous_actions=True, seed=cfg["seed"])
env.reset()
g = torch.Generator().manual_seed(cfg["seed"])
sizes = [env.get_agent_action_size(agent) for agent in env.agents]
draw = lambda count: [[torch.rand(n, size, generator=g) * 2 - 1 for size in sizes] for _ in range(count)]
switch = env.world.compiled_from_step
started = time.perf_counter()
chunk = draw(100)
for i in range((switch or 0) + cfg["warmup"]):  # on through the default mode's switch, as a long run
    env.step(chunk[i % 100])
warmup_s = time.perf_counter() - started
timed = draw(steps)
started = time.perf_counter()
for actions in timed:
    env.step(actions)
seconds = time.perf_counter() - started
import vmas_ros
print(json.dumps({"side": "vmas_ros", "version": vmas_ros.__version__, "num_envs": n, "steps": steps,
                  "ms_per_step": 1000 * seconds / steps, "warmup_s": warmup_s, "switch_step": switch,
                  "compiled": env.world.physics_compiled}))
"""


def jaxmarl_python(given: Optional[str]) -> str:
    """The interpreter that has JaxMARL: ``given``, else ``VMAS_ROS_JAXMARL_PYTHON``; a ValueError says how
    to make one when there is none, or when it cannot import jaxmarl."""
    python = given or os.environ.get("VMAS_ROS_JAXMARL_PYTHON")
    if not python:
        raise ValueError("give JaxMARL's interpreter with --jaxmarl-python PATH (or VMAS_ROS_JAXMARL_PYTHON), e.g. "
                         "after: python -m venv /opt/jaxmarl && /opt/jaxmarl/bin/pip install jaxmarl")
    if not Path(python).exists():
        raise ValueError(f"--jaxmarl-python {python!r} does not exist")
    probe = subprocess.run([python, "-c", "import jaxmarl"], capture_output=True, text=True)
    if probe.returncode != 0:
        raise ValueError(f"--jaxmarl-python {python!r} cannot import jaxmarl: {probe.stderr.strip()[-300:]}")
    return python


def _run_side(side: str, python: str, num_envs: int, steps: int, seed: int) -> dict:
    config = json.dumps({"num_envs": num_envs, "steps": steps, "warmup": WARMUP_STEPS, "seed": seed})
    env = {key: value for key, value in os.environ.items() if key != "VMAS_ROS_COMPILE"}
    command = [python, str(_SIDE_SCRIPT), config] if side == "JaxMARL" else [sys.executable, "-c", _VMAS_ROS_SIDE, config]
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"{side} at {num_envs} envs failed (exit {done.returncode}): {done.stderr.strip()[-2000:]}")
    return json.loads(lines[-1])


def run_jaxmarl_benchmark(python: str, num_envs: Sequence[int] = DEFAULT_NUM_ENVS, steps: int = DEFAULT_STEPS,
                          repeats: int = 3, seed: int = 0, progress: bool = True) -> List[dict]:
    """One row per env count: both sides' median ms per step over ``repeats`` alternating processes."""
    if repeats < 1 or steps < 1 or any(n < 1 for n in num_envs):
        raise ValueError(f"repeats, steps and env counts must be >= 1, got {repeats}, {steps}, {list(num_envs)}")
    from tqdm import tqdm

    rows = []
    bar = tqdm(total=len(num_envs) * repeats * 2, desc="bench jaxmarl", disable=not progress)
    for n in num_envs:
        runs: Dict[str, List[dict]] = {"vmas_ros": [], "JaxMARL": []}
        for repeat in range(repeats):
            order = ("vmas_ros", "JaxMARL") if repeat % 2 == 0 else ("JaxMARL", "vmas_ros")
            for side in order:
                runs[side].append(_run_side(side, python, n, steps, seed))
                bar.update(1)
        ours = statistics.median(run["ms_per_step"] for run in runs["vmas_ros"])
        theirs = statistics.median(run["ms_per_step"] for run in runs["JaxMARL"])
        rows.append({"num_envs": n, "steps": steps, "repeats": repeats, "vmas_ros_ms": ours, "jaxmarl_ms": theirs,
                     "ratio": theirs / ours, "switch_step": runs["vmas_ros"][0]["switch_step"],
                     "compiled": runs["vmas_ros"][0]["compiled"], "jaxmarl": runs["JaxMARL"][0]["version"],
                     "jax": runs["JaxMARL"][0]["jax"], "runs": runs})
    bar.close()
    return rows


def format_table(rows: List[dict]) -> str:
    lines = ["| envs | vmas_ros ms/step | JaxMARL ms/step | JaxMARL / vmas_ros | vmas_ros step | goal |",
             "|---:|---:|---:|---:|---|---|"]
    for row in rows:
        mode = f"compiled from step {row['switch_step']:,}" if row["compiled"] else "eager"
        met = "✓" if row["ratio"] >= 1 else "✗"
        lines.append(f"| {row['num_envs']:,} | {row['vmas_ros_ms']:.4f} | {row['jaxmarl_ms']:.4f} | "
                     f"{row['ratio']:.2f}x | {mode} | {met} at most JaxMARL's |")
    return "\n".join(lines)


def write_results(rows: List[dict], out: str) -> Dict[str, Path]:
    """``jaxmarl.md`` and ``jaxmarl.json`` in ``out``."""
    from vmas_ros.bench.report import write_table_and_rows

    return write_table_and_rows(rows, out, "jaxmarl", format_table(rows))
