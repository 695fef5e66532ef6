"""Memory probes and outputs shared by both soak modes (:mod:`vmas_ros.bench.soak` for the engine,
:mod:`vmas_ros.bench.soak_node` for sim_node): the RSS and live-tensor probes, a sample, the growth and
slope a verdict is judged on, and the CSV/JSON/PNG files a run writes.
"""
from __future__ import annotations

import csv
import gc
import json
import os
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import torch

__all__ = ["MB", "MemorySample", "growth_mb", "live_tensor_bytes", "rss_bytes", "slope_per_hour", "write_outputs"]

MB = 1024 * 1024


# ------------------------------------------------------------------- memory probes
def rss_bytes(pid: Optional[int] = None) -> int:
    """Resident set size of ``pid`` (default: this process): psutil when installed, else /proc.

    /proc/<pid>/statm is Linux-only but needs no extra package; its second field
    is the resident page count.
    """
    try:
        import psutil  # type: ignore[import-not-found]

        return int(psutil.Process(pid or os.getpid()).memory_info().rss)
    except ImportError:
        with open(f"/proc/{pid or 'self'}/statm") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def live_tensor_bytes(device: torch.device) -> int:
    """Bytes held by torch tensors on ``device`` that are still alive.

    On CUDA the caching allocator counts them (``memory_allocated``). The CPU
    allocator keeps no count, so we walk the garbage collector's objects and sum
    the distinct storages of live tensors: a tensor leak (a list that keeps every
    step's output) shows here long before it is visible in a noisy RSS. The walk
    is slow, which is why it runs once per sample interval.
    """
    if device.type == "cuda":
        return int(torch.cuda.memory_allocated(device))
    seen: Dict[int, int] = {}
    for obj in gc.get_objects():
        try:
            # type(), not isinstance: isinstance reads __class__, which some deprecated module proxies warn on
            if issubclass(type(obj), torch.Tensor) and obj.device.type == device.type:
                storage = obj.untyped_storage()
                seen[storage.data_ptr()] = storage.nbytes()
        except Exception:  # noqa: BLE001 - exotic tensor subclasses and half-built objects are skipped
            continue
    return sum(seen.values())


@dataclass
class MemorySample:
    """One sample of a soak run (``step`` is the engine step or the node's sim step)."""

    step: int
    wall_s: float
    rss_mb: float
    torch_mb: float
    finite: bool
    steps_per_s: float


def growth_mb(values: Sequence[float], warmup_index: int) -> float:
    """Growth of a memory series after warm-up: median of its last quarter minus median of its first quarter.

    Medians over quarters (at least one sample each), not single samples: the RSS
    of a torch process swings as the allocator returns and takes back pages, and
    a single transient (a bag chunk being flushed, a temporary during a reset)
    must neither hide nor fake a trend. A leak moves both medians apart.
    """
    tail = list(values[warmup_index:])
    if len(tail) < 2:
        return 0.0
    k = max(1, len(tail) // 4)
    return float(statistics.median(tail[-k:]) - statistics.median(tail[:k]))


def slope_per_hour(times_s: Sequence[float], values: Sequence[float]) -> float:
    """Least-squares slope of ``values`` over ``times_s``, per hour (0 with fewer than 2 points)."""
    n = len(times_s)
    if n < 2:
        return 0.0
    mt, mv = sum(times_s) / n, sum(values) / n
    var = sum((t - mt) ** 2 for t in times_s)
    if var == 0:
        return 0.0
    return float(sum((t - mt) * (v - mv) for t, v in zip(times_s, values)) / var * 3600.0)


# ------------------------------------------------------------------------- outputs
def write_outputs(result, out_dir: str, stem: str, x_label: str = "step", plot: bool = True) -> Dict[str, Path]:
    """``<stem>.csv`` (every sample), ``<stem>.json`` (the summary) and ``<stem>.png`` (memory over time)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / f"{stem}.csv", "json": out / f"{stem}.json"}
    samples = result.samples
    with paths["csv"].open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(asdict(samples[0]).keys()) if samples else ["step"])
        writer.writeheader()
        for s in samples:
            writer.writerow(asdict(s))
    summary = {k: v for k, v in asdict(result).items() if k != "samples"}
    summary["n_samples"] = len(samples)
    summary["written_at"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    paths["json"].write_text(json.dumps(summary, indent=2) + "\n")
    if plot and samples:
        try:
            paths["png"] = _plot(samples, out / f"{stem}.png", x_label, summary)
        except ImportError:
            print("note: matplotlib is not installed; no PNG written", file=sys.stderr)
    return paths


def _plot(samples: List[MemorySample], path: Path, x_label: str, summary: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs = [s.step if x_label == "step" else s.wall_s / 60 for s in samples]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    top.plot(xs, [s.rss_mb for s in samples], marker=".", label="RSS")
    top.set_ylabel("RSS (MB)")
    top.grid(alpha=0.3)
    bottom.plot(xs, [s.torch_mb for s in samples], marker=".", color="tab:orange")
    bottom.set_ylabel("live torch tensors (MB)" if "node" not in path.stem else "bag size (MB)")
    bottom.set_xlabel("step" if x_label == "step" else "wall time (min)")
    bottom.grid(alpha=0.3)
    verdict = "ok" if summary.get("ok") else "FAILED"
    title = f"{path.stem}: {verdict}, RSS growth after warm-up {summary.get('rss_growth_mb', 0):.1f} MB"
    top.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
