"""The MPE comparison of the VMAS paper (Fig. 2), with vmas_ros as a third side.

Task: ``simple_spread`` (3 agents, 3 landmarks), ``steps`` steps (100 in the
paper) against the number of parallel environments.

* ``vmas_ros`` and upstream ``vmas``: one batched env of ``num_envs`` copies
  (``make_env("simple_spread", num_envs=n, device=d, seed=0)``), stepped
  ``steps`` times.
* ``mpe`` (PettingZoo's ``mpe2.simple_spread_v3.parallel_env(N=3,
  continuous_actions=True, max_cycles=steps + 1)``): MPE is not vectorized, so,
  as in the paper, ``num_envs`` separate envs are stepped one after the other in
  a Python loop; the time for n envs is the sum over the n envs. Above
  ``mpe_max_envs`` only that many envs are really stepped and the time is
  extrapolated linearly (per-env time measured at the cap, times n); such rows
  have ``extrapolated: True``.

What is timed: the ``steps`` calls of ``step`` only. Env construction, the
reset before each repeat, and the random actions are not: the actions (uniform
in each action space) are generated once per env batch before timing, with the
side's own ``get_random_actions`` for VMAS/vmas_ros and one numpy sequence
shared by all MPE envs of a batch (MPE's step cost does not depend on the action
values). The sides are interleaved inside every repeat (A B C, A B C, ...) so
noise from other work on a shared machine hits them alike: quote the speed-up
ratios of one run.
"""
from __future__ import annotations

import argparse
import csv
import datetime as _dt
import gc
import importlib
import json
import os
import platform
import statistics
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from vmas_ros.bench.timing import Case, Timing, pinned_threads, time_alternating

__all__ = [
    "SIDES",
    "PEERS",
    "available_peers",
    "compute_ratios",
    "default_devices",
    "format_table",
    "machine_info",
    "run_mpe_benchmark",
    "write_results",
    "add_bench_arguments",
    "run_bench_command",
]

SCENARIO = "simple_spread"
N_AGENTS = 3
SIDES = ("vmas_ros", "vmas", "mpe")
PEERS = ("vmas", "mpe")
_PEER_MODULE = {"vmas": "vmas", "mpe": "mpe2"}
_PEER_INSTALL = {"vmas": "pip install vmas==1.5.2", "mpe": "pip install mpe2"}
_LABEL = {"vmas_ros": "vmas_ros", "vmas": "VMAS", "mpe": "MPE"}
BENCHMARKS = ("mpe",)

CSV_COLUMNS = [
    "run_id", "scenario", "side", "device", "num_envs", "steps", "repeats", "median_s", "min_s", "max_s",
    "per_step_ms", "env_steps_per_s", "extrapolated", "measured_envs", "measured_in_round", "threads",
    "times_s", "peak_rss_mb", "torch_peak_mb", "loadavg_1m",
]


# ----------------------------------------------------------------- validation
def default_devices() -> Tuple[str, ...]:
    """``("cpu",)``, plus ``"cuda"`` when torch sees a GPU."""
    return ("cpu", "cuda") if torch.cuda.is_available() else ("cpu",)


def _peer_installed(peer: str) -> bool:
    try:
        importlib.import_module(_PEER_MODULE[peer])
    except Exception:  # ImportError, or a broken install
        return False
    return True


def available_peers() -> Tuple[str, ...]:
    """The peers (``vmas``, ``mpe``) whose packages import here."""
    return tuple(peer for peer in PEERS if _peer_installed(peer))


def _positive_int(name: str, value, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a positive integer{' or None' if allow_none else ''}, got {value!r}")


def _validate(num_envs, steps, repeats, devices, peers, mpe_max_envs, threads, warmup) -> None:
    """Raise ValueError with a clear message for any bad argument."""
    if isinstance(num_envs, (int, str)) or not isinstance(num_envs, Sequence) or len(num_envs) == 0:
        raise ValueError(f"num_envs must be a non-empty list of positive integers, got {num_envs!r}")
    for n in num_envs:
        _positive_int("every num_envs", n)
    _positive_int("steps", steps)
    _positive_int("repeats", repeats)
    _positive_int("mpe_max_envs", mpe_max_envs, allow_none=True)
    _positive_int("threads", threads, allow_none=True)
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise ValueError(f"warmup must be a non-negative integer, got {warmup!r}")
    if devices is not None:
        if isinstance(devices, str) or len(devices) == 0:
            raise ValueError(f"devices must be a non-empty list such as ['cpu'], got {devices!r}")
        for device in devices:
            try:
                parsed = torch.device(device)
            except (RuntimeError, TypeError) as error:
                raise ValueError(f"unknown device {device!r}: {error}") from None
            if parsed.type not in ("cpu", "cuda"):
                raise ValueError(f"device must be cpu or cuda, got {device!r}")
            if parsed.type == "cuda" and not torch.cuda.is_available():
                raise ValueError(f"device {device!r} asked for, but torch sees no CUDA GPU here")
    if peers is not None:
        if isinstance(peers, str):
            raise ValueError(f"peers must be a list such as ['vmas', 'mpe'], got {peers!r}")
        unknown = [peer for peer in peers if peer not in PEERS]
        if unknown:
            raise ValueError(f"unknown peer(s) {unknown}; valid peers: {list(PEERS)}")


# -------------------------------------------------------------------- sides
def _vmas_case(side: str, num_envs: int, device: str, steps: int) -> Case:
    if side == "vmas_ros":
        import vmas_ros

        make = vmas_ros.make_env
    else:
        import vmas

        make = vmas.make_env
    env = make(SCENARIO, num_envs=num_envs, device=device, seed=0)
    env.reset()
    actions = [env.get_random_actions() for _ in range(steps)]  # generated once, not timed

    def run():
        for action in actions:
            env.step(action)

    return Case(run=run, setup=env.reset, device=device)


def _mpe_case(real_envs: int, steps: int, seed: int = 0) -> Case:
    from mpe2 import simple_spread_v3

    envs = [simple_spread_v3.parallel_env(N=N_AGENTS, continuous_actions=True, max_cycles=steps + 1)
            for _ in range(real_envs)]

    def reset():
        for index, env in enumerate(envs):
            env.reset(seed=seed + index)

    reset()
    agents = list(envs[0].possible_agents)
    space = envs[0].action_space(agents[0])
    table = np.random.default_rng(seed).uniform(space.low, space.high, size=(steps, len(agents)) + space.shape)
    table = table.astype(space.dtype)
    actions = [{agent: table[t, k] for k, agent in enumerate(agents)} for t in range(steps)]

    def run():  # as the paper's script: every step, each env in turn
        for action in actions:
            for env in envs:
                env.step(action)

    warm = envs[: min(real_envs, 4)]

    def warmup_run():  # warms the code paths without paying for thousands of envs twice
        for action in actions:
            for env in warm:
                env.step(action)

    return Case(run=run, setup=reset, warmup_run=warmup_run, device="cpu")


def _loadavg() -> Optional[float]:
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def _row(run_id, side, device, num_envs, steps, timing: Timing, measured_envs, round_n, loadavg) -> dict:
    scale = num_envs / measured_envs
    times = [t * scale for t in timing.times_s]
    median = statistics.median(times)
    return {
        "run_id": run_id,
        "scenario": SCENARIO,
        "side": side,
        "device": device,
        "num_envs": num_envs,
        "steps": steps,
        "repeats": timing.repeats,
        "median_s": median,
        "min_s": min(times),
        "max_s": max(times),
        "per_step_ms": median / steps * 1e3,
        "env_steps_per_s": num_envs * steps / median,
        "extrapolated": measured_envs != num_envs,
        "measured_envs": measured_envs,
        "measured_in_round": round_n,
        "threads": timing.threads,
        "times_s": times,
        "peak_rss_mb": timing.peak_rss_mb,
        "torch_peak_mb": timing.torch_peak_mb,
        "loadavg_1m": loadavg,
    }


def run_mpe_benchmark(
    num_envs: Sequence[int],
    steps: int = 100,
    repeats: int = 3,
    devices: Optional[Sequence[str]] = None,
    peers: Optional[Sequence[str]] = None,
    mpe_max_envs: Optional[int] = None,
    threads: Optional[int] = None,
    progress: bool = True,
    warmup: int = 1,
) -> List[dict]:
    """Time ``steps`` steps of simple_spread for each ``num_envs`` and side; one row per
    (side, device, num_envs). See the module docstring for what is timed.

    ``devices`` defaults to cpu (+ cuda if available) for vmas_ros and VMAS (MPE is
    CPU only); ``peers`` defaults to those of ``("vmas", "mpe")`` that are
    installed, and a requested peer that is not installed is skipped with a note
    on stderr. ``threads`` pins ``torch.set_num_threads`` for the run (restored
    afterwards). Raises ValueError for bad arguments.
    """
    _validate(num_envs, steps, repeats, devices, peers, mpe_max_envs, threads, warmup)
    devices = [str(torch.device(d)) for d in (devices if devices is not None else default_devices())]
    devices = list(dict.fromkeys(devices))
    requested = list(PEERS) if peers is None else list(dict.fromkeys(peers))
    active = []
    for peer in requested:
        if _peer_installed(peer):
            active.append(peer)
        elif peers is not None:
            print(f"note: peer {peer!r} is not installed ({_PEER_INSTALL[peer]}); skipped", file=sys.stderr)
    rounds = sorted(set(int(n) for n in num_envs))
    run_id = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()

    # plan: which cases each round measures (MPE above the cap is measured once, at the cap)
    plan = []
    cap_measured = False
    for n in rounds:
        sides = [("vmas_ros", d) for d in devices] + ([("vmas", d) for d in devices] if "vmas" in active else [])
        mpe_envs = None
        if "mpe" in active:
            if mpe_max_envs is None or n <= mpe_max_envs:
                mpe_envs = n
                cap_measured = cap_measured or n == mpe_max_envs
            elif not cap_measured:
                mpe_envs = mpe_max_envs
                cap_measured = True
        plan.append((n, sides, mpe_envs))

    from tqdm import tqdm

    total = sum(repeats * (len(sides) + (mpe_envs is not None)) for _, sides, mpe_envs in plan)
    rows: List[dict] = []
    cap_result: Optional[Tuple[Timing, int]] = None  # (timing at the cap, round it was measured in)
    with pinned_threads(threads), tqdm(total=total, disable=not progress, desc="mpe bench", unit="run",
                                       file=sys.stderr, dynamic_ncols=True) as bar:
        for n, sides, mpe_envs in plan:
            loadavg = _loadavg()
            bar.set_postfix_str(f"{n} envs: building", refresh=True)
            cases: Dict[str, Case] = {}
            for side, device in sides:
                cases[f"{side}/{device}"] = _vmas_case(side, n, device, steps)
            if mpe_envs is not None:
                cases["mpe/cpu"] = _mpe_case(mpe_envs, steps)
            bar.set_postfix_str(f"{n} envs: warm-up", refresh=True)

            def on_run(name, index, seconds, n=n):
                bar.set_postfix_str(f"{n} envs: {name} #{index + 1} {seconds:.3g}s", refresh=False)
                bar.update(1)

            timings = time_alternating(cases, repeats=repeats, warmup=warmup, on_run=on_run)
            for side, device in sides:
                rows.append(_row(run_id, side, device, n, steps, timings[f"{side}/{device}"], n, n, loadavg))
            if "mpe" in active:
                if mpe_envs is not None:
                    timing = timings["mpe/cpu"]
                    if mpe_envs == mpe_max_envs:
                        cap_result = (timing, n)
                    rows.append(_row(run_id, "mpe", "cpu", n, steps, timing, mpe_envs, n, loadavg))
                else:  # above the cap, measured in an earlier round
                    timing, round_n = cap_result
                    rows.append(_row(run_id, "mpe", "cpu", n, steps, timing, mpe_max_envs, round_n, loadavg))
            del cases, timings
            gc.collect()
    return rows


# ------------------------------------------------------------------- ratios
def compute_ratios(rows: Sequence[dict]) -> List[dict]:
    """Speed-up of vmas_ros over each peer, per num_envs and vmas_ros device, from rows
    of the same run (same ``run_id``). ``speedup`` is peer median / vmas_ros median;
    ``speedup_paired`` the median of per-repeat ratios when both were measured in the
    same alternating round (None otherwise, e.g. for a reused extrapolation)."""
    index = {(r["run_id"], r["side"], r["device"], r["num_envs"]): r for r in rows}
    ratios = []
    for row in rows:
        if row["side"] != "vmas_ros":
            continue
        for peer in PEERS:
            peer_device = row["device"] if peer == "vmas" else "cpu"
            other = index.get((row["run_id"], peer, peer_device, row["num_envs"]))
            if other is None:
                continue
            paired = None
            if other["measured_in_round"] == row["measured_in_round"] and len(other["times_s"]) == len(row["times_s"]):
                paired = statistics.median(p / o for p, o in zip(other["times_s"], row["times_s"]))
            ratios.append({
                "run_id": row["run_id"],
                "num_envs": row["num_envs"],
                "device": row["device"],
                "peer": peer,
                "peer_device": peer_device,
                "vmas_ros_s": row["median_s"],
                "peer_s": other["median_s"],
                "speedup": other["median_s"] / row["median_s"],
                "speedup_paired": paired,
                "peer_extrapolated": bool(other["extrapolated"]),
            })
    return ratios


# -------------------------------------------------------------------- table
def _fmt_s(seconds: float) -> str:
    return f"{seconds:.4f}" if seconds < 10 else f"{seconds:.2f}"


def _columns(rows) -> List[Tuple[str, str]]:
    present = {(r["side"], r["device"]) for r in rows}
    devices = sorted({d for _, d in present}, key=lambda d: (d != "cpu", d))
    return [(side, device) for side in SIDES for device in devices if (side, device) in present]


def _extrapolation_note(rows) -> Optional[str]:
    capped = sorted({r["measured_envs"] for r in rows if r["extrapolated"]})
    if not capped:
        return None
    return (f"\\* extrapolated: MPE was really stepped for {', '.join(map(str, capped))} envs and the time "
            f"was scaled linearly to num_envs (per-env time at the cap x num_envs).")


def format_table(rows: Sequence[dict]) -> str:
    """A markdown table: num_envs, seconds for ``steps`` steps per side, speed-ups of
    vmas_ros over VMAS and MPE (ratio of medians, one run). ``*`` marks extrapolated times."""
    if not rows:
        return "(no results)"
    columns = _columns(rows)
    multi_device = len({d for _, d in columns}) > 1
    ratios = compute_ratios(rows)
    ratio_keys = sorted({(r["device"], r["peer"]) for r in ratios},
                        key=lambda k: (k[0] != "cpu", k[0], PEERS.index(k[1])))
    steps = sorted({r["steps"] for r in rows})
    head = ["num_envs"] + [f"{_LABEL[s]} {d} (s)" for s, d in columns]
    for device, peer in ratio_keys:
        head.append(f"speed-up vs {_LABEL[peer]}" + (f" ({device})" if multi_device else ""))
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---:" for _ in head) + "|"]
    by_key = {(r["side"], r["device"], r["num_envs"]): r for r in rows}
    ratio_by = {(r["num_envs"], r["device"], r["peer"]): r for r in ratios}
    for n in sorted({r["num_envs"] for r in rows}):
        cells = [str(n)]
        for side, device in columns:
            row = by_key.get((side, device, n))
            cells.append("-" if row is None else _fmt_s(row["median_s"]) + ("\\*" if row["extrapolated"] else ""))
        for device, peer in ratio_keys:
            ratio = ratio_by.get((n, device, peer))
            cells.append("-" if ratio is None else f"{ratio['speedup']:.2f}x" + ("\\*" if ratio["peer_extrapolated"] else ""))
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"Median seconds for {'/'.join(map(str, steps))} steps of {SCENARIO} (random actions, "
                 f"not timed); speed-up = peer time / vmas_ros time in the same run.")
    note = _extrapolation_note(rows)
    if note:
        lines.append(note)
    return "\n".join(lines)


# ------------------------------------------------------------ machine, files
def _version(package: str) -> Optional[str]:
    try:
        from importlib.metadata import version

        return version(package)
    except Exception:
        return None


def _vmas_ros_version() -> str:
    from vmas_ros import __version__

    return __version__


def _cpu_model() -> Optional[str]:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def machine_info(rows: Sequence[dict]) -> dict:
    """Where and how ``rows`` were measured: versions, threads, CPUs, date."""
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    devices = sorted({r["device"] for r in rows})
    info = {
        "date": rows[0]["run_id"] if rows else None,
        "written": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
        "torch": torch.__version__,
        "threads": sorted({r["threads"] for r in rows}),
        "cpu_count": os.cpu_count(),
        "cpus_usable": usable,
        "cpu_model": _cpu_model(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "vmas_ros": _version("vmas_ros") or _vmas_ros_version(),
        "vmas": _version("vmas"),
        "mpe2": _version("mpe2"),
        "numpy": np.__version__,
        "devices": devices,
    }
    if any(d.startswith("cuda") for d in devices) and torch.cuda.is_available():
        info["cuda_device"] = torch.cuda.get_device_name(0)
    return info


def _title(info: dict, steps: Sequence[int]) -> str:
    threads = "/".join(map(str, info["threads"]))
    date = (info["date"] or "")[:10]
    cpu = info.get("cpu_model") or "CPU"
    return (f"{SCENARIO}, {'/'.join(map(str, steps))} steps vs parallel envs\n"
            f"torch {info['torch']}, {threads} torch thread(s), {info['cpus_usable']} of {info['cpu_count']} CPUs "
            f"({cpu}), {date}")


def _plot(rows: Sequence[dict], path: Path, info: dict) -> None:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    colors = {"vmas_ros": "tab:green", "vmas": "tab:blue", "mpe": "tab:orange"}
    styles = {"cpu": "o", "cuda": "s"}
    fig, ax = plt.subplots(figsize=(8, 5), dpi=110)
    any_extrapolated = False
    for side, device in _columns(rows):
        line = sorted((r for r in rows if r["side"] == side and r["device"] == device), key=lambda r: r["num_envs"])
        measured = [r for r in line if not r["extrapolated"]]
        extra = [r for r in line if r["extrapolated"]]
        color, marker = colors[side], styles.get(device.split(":")[0], "^")
        label = f"{_LABEL[side]} ({device.upper() if device == 'cpu' else device})"
        if side == "mpe":
            label += ", one env at a time"
        if measured:
            ax.plot([r["num_envs"] for r in measured], [r["median_s"] for r in measured], marker=marker,
                    color=color, linestyle="-", label=label)
        if extra:
            any_extrapolated = True
            bridge = measured[-1:] + extra
            ax.plot([r["num_envs"] for r in bridge], [r["median_s"] for r in bridge], color=color, linestyle="--")
            ax.plot([r["num_envs"] for r in extra], [r["median_s"] for r in extra], marker=marker, color=color,
                    linestyle="none", markerfacecolor="none", markersize=8,
                    label=None if measured else label)
        # spread of the repeats
        ax.vlines([r["num_envs"] for r in line], [r["min_s"] for r in line], [r["max_s"] for r in line],
                  color=color, alpha=0.5)
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    ticks = sorted({r["num_envs"] for r in rows})
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:,.0f}"))
    ax.set_xlabel("number of parallel environments")
    steps = sorted({r["steps"] for r in rows})
    ax.set_ylabel(f"seconds for {'/'.join(map(str, steps))} steps")
    ax.grid(True, which="both", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if any_extrapolated:
        capped = ", ".join(map(str, sorted({r["measured_envs"] for r in rows if r["extrapolated"]})))
        handles.append(Line2D([], [], color="gray", linestyle="--", marker="o", markerfacecolor="none"))
        labels.append(f"extrapolated linearly (stepped {capped} envs)")
    repeats = "/".join(map(str, sorted({r["repeats"] for r in rows})))
    handles.append(Line2D([], [], color="gray", alpha=0.5, marker="|", linestyle="none", markersize=10))
    labels.append(f"min-max of {repeats} repeats (point: median)")
    ax.legend(handles, labels, loc="upper left", fontsize=8)
    ax.set_title(_title(info, steps), fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _csv_value(value):
    if value is None:
        return ""
    if isinstance(value, list):
        return ";".join(f"{v:.6g}" for v in value)
    return value


def write_results(rows: Sequence[dict], out_dir, plot: bool = True) -> Dict[str, Path]:
    """Write ``mpe_benchmark.csv``, ``.json`` (rows, ratios, machine info), ``.md`` (the
    table) and, with ``plot``, ``.png`` (paper Fig. 2 style; needs matplotlib) into
    ``out_dir``. Returns the paths by kind."""
    if not rows:
        raise ValueError("no rows to write")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [dict(r) for r in rows]
    info = machine_info(rows)
    ratios = compute_ratios(rows)
    paths = {"csv": out / "mpe_benchmark.csv", "json": out / "mpe_benchmark.json", "md": out / "mpe_benchmark.md"}
    with open(paths["csv"], "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_value(row.get(k)) for k in CSV_COLUMNS})
    notes = [
        "Timed: the steps calls of step() only; env construction, the reset before each repeat and the random "
        "actions (generated once beforehand) are not timed.",
        "MPE (mpe2.simple_spread_v3.parallel_env, continuous actions) steps each env separately in a Python loop, "
        "as in the VMAS paper; its time for n envs is the sum over the n envs.",
        "Sides alternate inside every repeat (A B C, A B C, ...); compare the ratios of one run.",
        "peak_rss_mb is the whole process's high-water mark when a round ended, not per side.",
    ]
    note = _extrapolation_note(rows)
    if note:
        notes.append(note.replace("\\*", "*"))
    document = {
        "benchmark": "mpe_comparison",
        "scenario": SCENARIO,
        "machine": info,
        "notes": notes,
        "rows": rows,
        "ratios": ratios,
    }
    with open(paths["json"], "w", encoding="utf-8") as handle:
        json.dump(document, handle, indent=2, allow_nan=False)
    header = f"# MPE comparison ({SCENARIO})\n\n{_title(info, sorted({r['steps'] for r in rows})).replace(chr(10), '. ')}\n\n"
    paths["md"].write_text(header + format_table(rows) + "\n", encoding="utf-8")
    if plot:
        paths["png"] = out / "mpe_benchmark.png"
        _plot(rows, paths["png"], info)
    return paths


# ---------------------------------------------------------------------- CLI
def add_bench_arguments(parser: argparse.ArgumentParser, with_benchmark_name: bool = True) -> argparse.ArgumentParser:
    """Add the ``bench`` options to ``parser``. With ``with_benchmark_name`` a positional
    benchmark name (only ``mpe`` today, default ``mpe``) is added first, for
    ``vmas-ros bench mpe ...``; pass False when ``mpe`` is already a subcommand."""
    if with_benchmark_name:
        parser.add_argument("benchmark", nargs="?", default="mpe", help="which benchmark: mpe (default)")
    # dest is not ``num_envs``: cli.main compares args.num_envs with an int
    parser.add_argument("--num-envs", dest="bench_num_envs", type=int, nargs="+", default=[1, 10, 100, 1000],
                        metavar="N", help="numbers of parallel envs (default: 1 10 100 1000)")
    parser.add_argument("--steps", type=int, default=100, help="steps per timed run (default 100, as the paper)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per side and num_envs (default 3)")
    parser.add_argument("--warmup", type=int, default=1, help="untimed warm-up runs per side (default 1)")
    parser.add_argument("--devices", nargs="+", default=None, metavar="DEVICE",
                        help="torch devices for vmas_ros/VMAS (default: cpu, plus cuda if available)")
    parser.add_argument("--peers", nargs="*", default=None, metavar="PEER",
                        help="peers to compare with: vmas, mpe (default: those installed)")
    parser.add_argument("--mpe-max-envs", type=int, default=None, metavar="N",
                        help="step at most N MPE envs; above, extrapolate linearly (default: no cap)")
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads for the run (default: torch's)")
    parser.add_argument("--out", default="bench_results", help="output folder (default bench_results/)")
    parser.add_argument("--no-plot", action="store_true", help="do not write the PNG")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def run_bench_command(args: argparse.Namespace) -> int:
    """Run the benchmark from parsed ``add_bench_arguments`` options: 0 on success, 2 on bad arguments."""
    benchmark = getattr(args, "benchmark", "mpe") or "mpe"
    if benchmark not in BENCHMARKS:
        print(f"vmas-ros bench: unknown benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}", file=sys.stderr)
        return 2
    num_envs = getattr(args, "bench_num_envs", None)
    if num_envs is None:
        num_envs = getattr(args, "num_envs", [1, 10, 100, 1000])
    if isinstance(num_envs, int):
        num_envs = [num_envs]
    options = dict(
        num_envs=list(num_envs), steps=args.steps, repeats=getattr(args, "repeats", 3),
        devices=getattr(args, "devices", None), peers=getattr(args, "peers", None),
        mpe_max_envs=getattr(args, "mpe_max_envs", None), threads=getattr(args, "threads", None),
        warmup=getattr(args, "warmup", 1),
    )
    try:
        _validate(**options)
    except ValueError as error:
        print(f"vmas-ros bench: {error}", file=sys.stderr)
        return 2
    plot = not getattr(args, "no_plot", False)
    if plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            print("note: matplotlib is not installed (pip install 'vmas_ros[bench]'); no PNG will be written",
                  file=sys.stderr)
            plot = False
    rows = run_mpe_benchmark(progress=not getattr(args, "no_progress", False), **options)
    paths = write_results(rows, getattr(args, "out", "bench_results"), plot=plot)
    print(format_table(rows))
    print()
    for path in paths.values():
        print(f"wrote {path}")
    return 0
