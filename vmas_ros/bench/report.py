"""Results of the MPE benchmark: speed-up ratios, the markdown table, machine
information, the plot (paper Fig. 2 style) and the files written by
:func:`write_results`. Public names are re-exported by :mod:`vmas_ros.bench.mpe`.
"""
from __future__ import annotations

import csv
import datetime as _dt
import json
import os
import platform
import statistics
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch

from vmas_ros.bench.common import _LABEL, CSV_COLUMNS, PEERS, SCENARIO, SIDES

__all__ = [
    "compute_ratios", "finish_results", "format_table", "machine_info", "plot_available", "start_results",
    "write_csv", "write_results",
]


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
    from vmas_ros.compat.version import __version__

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


def plot_available(wanted: bool) -> bool:
    """Whether a benchmark should write PNGs: ``wanted`` and matplotlib importable (else a note on stderr)."""
    if not wanted:
        return False
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print("note: matplotlib is not installed (pip install 'vmas_ros[bench]'); no PNG will be written",
              file=sys.stderr)
        return False
    return True


def write_csv(path: Path, rows: Sequence[dict], columns: Sequence[str]) -> None:
    """One CSV line per row, only ``columns`` (lists joined, floats kept exact)."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(columns), extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_value(row.get(k)) for k in columns})


def start_results(rows: Sequence[dict], out_dir, stem: str,
                  columns: Sequence[str]) -> Tuple[Path, List[dict], dict, Dict[str, Path]]:
    """Create ``out_dir`` and write ``<stem>.csv`` (``columns`` of every row).

    Returns ``(out, rows, info, paths)``: the folder, a copy of the rows, the
    machine they ran on, and the csv/json/md paths by kind, for
    :func:`finish_results` to complete.
    """
    if not rows:
        raise ValueError("no rows to write")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [dict(r) for r in rows]
    paths = {kind: out / f"{stem}.{kind}" for kind in ("csv", "json", "md")}
    write_csv(paths["csv"], rows, columns)
    return out, rows, machine_info(rows), paths


def finish_results(paths: Dict[str, Path], document: dict, markdown: str) -> None:
    """Write a benchmark's JSON ``document`` (no NaN) and its Markdown report."""
    with open(paths["json"], "w", encoding="utf-8") as handle:
        json.dump(document, handle, indent=2, allow_nan=False)
    paths["md"].write_text(markdown + "\n", encoding="utf-8")


def write_results(rows: Sequence[dict], out_dir, plot: bool = True) -> Dict[str, Path]:
    """Write ``mpe_benchmark.csv``, ``.json`` (rows, ratios, machine info), ``.md`` (the
    table) and, with ``plot``, ``.png`` (paper Fig. 2 style; needs matplotlib) into
    ``out_dir``. Returns the paths by kind."""
    out, rows, info, paths = start_results(rows, out_dir, "mpe_benchmark", CSV_COLUMNS)
    ratios = compute_ratios(rows)
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
    header = f"# MPE comparison ({SCENARIO})\n\n{_title(info, sorted({r['steps'] for r in rows})).replace(chr(10), '. ')}\n\n"
    finish_results(paths, document, header + format_table(rows))
    if plot:
        paths["png"] = out / "mpe_benchmark.png"
        _plot(rows, paths["png"], info)
    return paths


def write_table_and_rows(rows: List[dict], out: str, stem: str, table: str) -> Dict[str, Path]:
    """``<stem>.md`` (``table``) and ``<stem>.json`` (every row) in ``out``, created if needed: what the
    process, torchrl and jaxmarl benchmarks write."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"md": folder / f"{stem}.md", "json": folder / f"{stem}.json"}
    paths["md"].write_text(table + "\n")
    paths["json"].write_text(json.dumps(rows, indent=1))
    return paths
