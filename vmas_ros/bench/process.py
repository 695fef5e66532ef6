"""``vmas-ros bench process``: what a short script costs, measured as a whole process, against VMAS.

A user's script imports the library, makes an env and steps it N times.
Everything it pays shows here, and nowhere in a per-step benchmark: imports,
building the world, compiling (in the default mode), memory. Each run is a
fresh interpreter (``python -c``) that does exactly that, with random actions
drawn from a seeded generator; the parent times it from start to exit and
reads its peak RSS from the kernel (``os.wait4``). Before a workload is timed,
one untimed process per side leaves the files it reads in the page cache and
its bytecode cached, as on a user's machine. vmas_ros and VMAS
alternate within every repeat, in the default mode (``VMAS_ROS_COMPILE``
removed from the child's environment) unless ``--process-mode`` says otherwise.

Workloads are ``<scenario>_<num_envs>``: ``transport_32``, ``navigation_60``
(the size of TorchRL's multi-agent PPO tutorial), ``simple_spread_1``, ...
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

__all__ = ["PROCESS_MODES", "parse_workload", "run_once", "run_process_benchmark", "format_table"]

#: how vmas_ros steps in the child: as make_env decides without flags, or forced either way
PROCESS_MODES = {"default": None, "eager": "0", "compiled": "1"}
DEFAULT_WORKLOADS = ("transport_32", "navigation_60")
DEFAULT_STEPS = (100, 1_000, 10_000)

_SCRIPT = r"""
import sys, json
cfg = json.loads(sys.argv[1])
import torch
if cfg["threads"]:
    torch.set_num_threads(cfg["threads"])
from importlib import import_module
make_env = import_module(cfg["module"]).make_env
n = cfg["num_envs"]
env = make_env(cfg["scenario"], num_envs=n, device="cpu", continuous_actions=True, seed=cfg["seed"])
env.reset()
g = torch.Generator().manual_seed(cfg["seed"])
sizes = [env.get_agent_action_size(agent) for agent in env.agents]
for _ in range(cfg["steps"]):
    env.step([torch.rand(n, size, generator=g) * 2 - 1 for size in sizes])
"""


def parse_workload(name: str) -> tuple:
    """``"transport_32"`` -> ``("transport", 32)``; a ValueError names a bad one."""
    scenario, _, count = name.rpartition("_")
    if not scenario or not count.isdigit() or int(count) < 1:
        raise ValueError(f"process workload must be <scenario>_<num_envs>, e.g. transport_32, got {name!r}")
    from vmas_ros.scenarios import list_scenarios

    if scenario not in list_scenarios():
        raise ValueError(f"process workload {name!r}: unknown scenario {scenario!r}")
    return scenario, int(count)


def run_once(side: str, scenario: str, num_envs: int, steps: int, seed: int = 0, mode: str = "default",
             threads: Optional[int] = None, cold_cache: bool = False) -> Dict[str, float]:
    """One fresh process of ``side`` (``vmas_ros`` or ``vmas``): ``{"seconds", "peak_rss_mb"}``.

    ``cold_cache`` gives a vmas_ros child an empty compile cache of its own (``TORCHINDUCTOR_CACHE_DIR``),
    as on a machine's first compile; otherwise it shares the user's, warm from earlier runs.
    Raises RuntimeError with the child's last lines when it fails.
    """
    if cold_cache and side == "vmas_ros":
        with tempfile.TemporaryDirectory(prefix="vmas_ros_cold_cache_") as cache:
            return _run_child(side, scenario, num_envs, steps, seed, mode, threads, {"TORCHINDUCTOR_CACHE_DIR": cache})
    return _run_child(side, scenario, num_envs, steps, seed, mode, threads, {})


def _run_child(side: str, scenario: str, num_envs: int, steps: int, seed: int, mode: str, threads: Optional[int],
               extra_environ: Dict[str, str]) -> Dict[str, float]:
    config = {"module": side, "scenario": scenario, "num_envs": num_envs, "steps": steps, "seed": seed,
              "threads": threads}
    environ = dict(os.environ)
    environ.pop("VMAS_ROS_COMPILE", None)
    # as on a user's machine, where bytecode is cached (an installed wheel's at install time, as VMAS's is)
    environ.pop("PYTHONDONTWRITEBYTECODE", None)
    if side == "vmas_ros" and PROCESS_MODES[mode] is not None:
        environ["VMAS_ROS_COMPILE"] = PROCESS_MODES[mode]
    environ.update(extra_environ)
    start = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-c", _SCRIPT, json.dumps(config)], env=environ,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    error = child.stderr.read().decode(errors="replace")
    child.stderr.close()
    if child.returncode != 0:
        raise RuntimeError(f"{side} {scenario} x{num_envs}, {steps} steps exited {child.returncode}: {error[-800:]}")
    return {"seconds": seconds, "peak_rss_mb": usage.ru_maxrss / 1024}


def run_process_benchmark(workloads: Sequence[str], steps: Sequence[int], repeats: int, mode: str = "default",
                          threads: Optional[int] = None, progress: bool = True, cold_cache: bool = False) -> List[dict]:
    """Every workload at every step count, ``repeats`` times per side, the sides alternating; one row each
    with the medians and every sample. ``cold_cache``: each vmas_ros process compiles from an empty cache."""
    from tqdm import tqdm

    if mode not in PROCESS_MODES:
        raise ValueError(f"--process-mode must be one of {', '.join(PROCESS_MODES)}, got {mode!r}")
    if repeats < 1 or not steps or min(steps) < 1:
        raise ValueError(f"repeats and every step count must be >= 1, got repeats={repeats}, steps={list(steps)}")
    parsed = [(name, *parse_workload(name)) for name in workloads]
    rows = []
    total = len(parsed) * len(steps) * repeats * 2
    with tqdm(total=total, desc="processes", disable=not progress) as bar:
        for name, scenario, num_envs in parsed:
            for side in ("vmas_ros", "vmas"):  # untimed: caches each side's bytecode and files alike
                run_once(side, scenario, num_envs, 1, mode="eager", threads=threads)
            for count in steps:
                samples: Dict[str, List[dict]] = {"vmas_ros": [], "vmas": []}
                for repeat in range(repeats):
                    order = ("vmas_ros", "vmas") if repeat % 2 == 0 else ("vmas", "vmas_ros")
                    for side in order:
                        samples[side].append(run_once(side, scenario, num_envs, count, mode=mode, threads=threads,
                                                      cold_cache=cold_cache))
                        bar.update()
                row = {"workload": name, "scenario": scenario, "num_envs": num_envs, "steps": count, "mode": mode,
                       "repeats": repeats, "threads": threads, "cold_cache": cold_cache}
                for side, runs in samples.items():
                    row[f"{side}_s"] = statistics.median(r["seconds"] for r in runs)
                    row[f"{side}_peak_mb"] = statistics.median(r["peak_rss_mb"] for r in runs)
                    row[f"{side}_samples_s"] = [round(r["seconds"], 3) for r in runs]
                row["time_ratio"] = row["vmas_ros_s"] / row["vmas_s"]
                row["memory_ratio"] = row["vmas_ros_peak_mb"] / row["vmas_peak_mb"]
                rows.append(row)
    return rows


def format_table(rows: List[dict]) -> str:
    """Markdown: one row per workload and step count; ratios are vmas_ros / VMAS (below 1: vmas_ros is cheaper)."""
    lines = ["| workload | steps | vmas_ros s | VMAS s | time ratio | vmas_ros peak MB | VMAS peak MB | memory ratio |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['workload']} | {r['steps']:,} | {r['vmas_ros_s']:.2f} | {r['vmas_s']:.2f} | "
                     f"{r['time_ratio']:.2f}x | {r['vmas_ros_peak_mb']:.0f} | {r['vmas_peak_mb']:.0f} | "
                     f"{r['memory_ratio']:.2f}x |")
    return "\n".join(lines)


def write_results(rows: List[dict], out: str) -> Dict[str, Path]:
    """``process.md``, ``process.json`` and (with matplotlib) ``process.png`` in ``out``."""
    from vmas_ros.bench.report import write_table_and_rows

    paths = write_table_and_rows(rows, out, "process", format_table(rows))
    if _plot(rows, Path(out) / "process.png"):
        paths["png"] = Path(out) / "process.png"
    return paths


def _plot(rows: List[dict], path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    names = list(dict.fromkeys(r["workload"] for r in rows))
    figure, axes = plt.subplots(1, len(names), figsize=(4.5 * len(names), 3.4), squeeze=False)
    for axis, name in zip(axes[0], names):
        mine = [r for r in rows if r["workload"] == name]
        steps = [r["steps"] for r in mine]
        axis.plot(steps, [r["vmas_ros_s"] for r in mine], "o-", label="vmas_ros")
        axis.plot(steps, [r["vmas_s"] for r in mine], "s--", label="VMAS 1.5.2")
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xlabel("steps in the process")
        axis.set_ylabel("whole process, s")
        axis.set_title(name, fontsize=9)
        axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return True
