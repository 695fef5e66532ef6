"""Results of the benchmark suite (:mod:`vmas_ros.bench.suite`): ratios against the
project's targets, the markdown tables, the two plots and the files in ``--out``.

Kept apart from the runner so a report can be rebuilt from saved or synthetic
rows (the tests feed it rows they made up to check the met/not-met logic).
Ratios are always ratios of the medians of one run, never of different runs.

The two agent curves, overlapping spheres (``scaling_agents``) and a swarm
(``scaling_agents_sparse``), share one plot with a dashed line of linear cost, so
that the swarm's cost per agent can be read against it.

With ``--modes eager compiled`` a point has up to three sides: ``vmas_ros``
(eager), ``vmas_ros_compiled`` and the peer. Each vmas_ros side gets its own
ratio against the peer, and a target counts as met when either ratio meets it
(``met_by`` says which; eager is named when both do), because the compiled
path is a supported way to run vmas_ros, not a different library. Without
compiled rows every table is exactly what it was before modes existed.
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from vmas_ros.bench.common import _LABEL, COMPILED_SIDE
from vmas_ros.bench.report import finish_results, start_results
from vmas_ros.bench.suite_cases import SPHERE_SPACING, SWARM_SPACING

__all__ = ["SUITE_COLUMNS", "TARGETS", "CURVES", "PLOTS", "evaluate_target", "format_suite_table", "measured_modes",
           "summarize", "write_suite_results"]

#: the project's speed and memory targets: (op, value) on the ratio. Time: peer / vmas_ros (speed-up, higher
#: is better). Memory: vmas_ros / peer peak RSS (lower is better).
TARGETS: Dict[str, Tuple[str, float]] = {
    "spread_1": (">=", 5.0),
    "spread_30k": (">=", 2.0),
    "transport_10k": (">=", 3.0),
    "flocking_10k": (">=", 10.0),
    "discovery_1k": (">=", 10.0),
    "spheres_100": (">=", 20.0),
    "spread_60": (">=", 50.0),
    "memory_30k": ("<=", 1.0),
    "mpe_1k": (">=", 300.0),
}
#: curve workloads and the variable on their x axis
CURVES = {"scaling_envs": "num_envs", "scaling_agents": "n_agents", "scaling_agents_sparse": "n_agents"}
#: the PNGs: kind in the returned paths -> (file name, the curves drawn on its axes)
PLOTS = {"envs_png": ("suite_envs.png", ("scaling_envs",)),
         "agents_png": ("suite_agents.png", ("scaling_agents", "scaling_agents_sparse"))}
#: how the spheres of each agent curve start: (legend name, sentence under its table)
_LAYOUTS = {
    "scaling_agents": ("overlapping", f"Spheres of radius 0.05 uniform in a square of side {SPHERE_SPACING:g}·√N: "
                                      f"most of it covered, many overlapping."),
    "scaling_agents_sparse": ("swarm", f"A swarm: spheres of radius 0.05 uniform in a square of side "
                                       f"{SWARM_SPACING:g}·√N, about 3% covered; one untimed step first."),
}
#: the sides that are vmas_ros (eager or compiled); any other side of a point is its peer
OURS = ("vmas_ros", COMPILED_SIDE)

SUITE_COLUMNS = [
    "run_id", "workload", "scenario", "side", "status", "note", "device", "num_envs", "n_agents", "steps",
    "repeats", "metric", "value", "unit", "median_s", "min_s", "max_s", "per_step_ms", "env_steps_per_s",
    "extrapolated", "measured_envs", "threads", "times_s", "rss_mb", "baseline_rss_mb", "peak_rss_mb",
    "loadavg_1m", "compiled", "default_mode", "first_run_s",
]


# ------------------------------------------------------------------ ratios
def evaluate_target(ratio: Optional[float], target: Optional[Tuple[str, float]]) -> Optional[bool]:
    """True/False when there is both a ratio and a target, else None."""
    if ratio is None or target is None:
        return None
    op, value = target
    if op == ">=":
        return ratio >= value
    if op == "<=":
        return ratio <= value
    raise ValueError(f"unknown target operator {op!r}; valid: '>=', '<='")


def _status(row: Optional[dict]) -> str:
    if row is None:
        return "missing"
    if row.get("status", "ok") == "ok":
        return "ok"
    return f"{row['status']}: {row.get('note', '')}".rstrip(": ")


def _ratio_of(ours: dict, theirs: dict, metric: str) -> float:
    """Memory: ours / theirs peak RSS (lower is better); time: theirs / ours median (a speed-up)."""
    return ours["value"] / theirs["value"] if metric == "memory" else theirs["median_s"] / ours["median_s"]


def summarize(rows: Sequence[dict], targets: Mapping[str, Tuple[str, float]] = TARGETS) -> List[dict]:
    """One entry per measured point (workload, num_envs, n_agents) of each run, in row order:
    every side's value, the ratios of their medians, the target and whether it is met.

    ``vmas_ros`` is the value of the side named vmas_ros (eager, or compiled when only
    compiled was measured: ``vmas_ros_mode`` says which); ``compiled`` that of
    ``vmas_ros_compiled``. ``met`` is the target checked on the better of ``ratio`` and
    ``compiled_ratio`` (memory: ``ratio`` only, it is measured eager) and ``met_by`` the
    mode that met it, "eager" when both do, None when not met."""
    groups: Dict[tuple, Dict[str, dict]] = {}
    for row in rows:
        key = (row["run_id"], row["workload"], row["num_envs"], row.get("n_agents"))
        groups.setdefault(key, {})[row["side"]] = row
    summary = []
    for (run_id, workload, num_envs, n_agents), sides in groups.items():
        ours, comp = sides.get("vmas_ros"), sides.get(COMPILED_SIDE)
        peer_name = next((side for side in sides if side not in OURS), "vmas")
        theirs = sides.get(peer_name)
        ours_ok, comp_ok, theirs_ok = (_status(r) == "ok" for r in (ours, comp, theirs))
        metric = (ours or comp or theirs)["metric"]
        ratio = _ratio_of(ours, theirs, metric) if ours_ok and theirs_ok else None
        compiled_ratio = _ratio_of(comp, theirs, metric) if comp_ok and theirs_ok else None
        target = None if workload in CURVES else targets.get(workload)
        mode = None if ours is None else "compiled" if ours.get("compiled") else "eager"
        default_mode = bool(ours and ours.get("default_mode"))
        met_eager = evaluate_target(ratio, target)
        met_compiled = None if metric == "memory" else evaluate_target(compiled_ratio, target)
        met = True if True in (met_eager, met_compiled) else False if False in (met_eager, met_compiled) else None
        summary.append({
            "run_id": run_id, "workload": workload, "num_envs": num_envs, "n_agents": n_agents, "metric": metric,
            "unit": "MB" if metric == "memory" else "ms/step", "peer": peer_name,
            "vmas_ros": ours["value"] if ours_ok else None,
            "peer_value": theirs["value"] if theirs_ok else None,
            "vmas_ros_env_steps_per_s": ours.get("env_steps_per_s") if ours_ok else None,
            "peer_env_steps_per_s": theirs.get("env_steps_per_s") if theirs_ok else None,
            "vmas_ros_baseline_mb": ours.get("baseline_rss_mb") if ours_ok else None,
            "peer_baseline_mb": theirs.get("baseline_rss_mb") if theirs_ok else None,
            "ratio": ratio,
            "ratio_kind": "vmas_ros / peer peak RSS" if metric == "memory" else "peer time / vmas_ros time",
            "target": None if target is None else f"{target[0]} {target[1]:g}x",
            "met": met,
            "met_by": mode if met_eager else "compiled" if met_compiled else None,
            "status": _status(ours), "peer_status": _status(theirs),
            "peer_extrapolated": bool(theirs.get("extrapolated")) if theirs_ok else False,
            "vmas_ros_mode": mode, "default_mode": default_mode,
            "first_run_s": ours.get("first_run_s") if ours_ok else None,
            "compiled": comp["value"] if comp_ok else None,
            "compiled_env_steps_per_s": comp.get("env_steps_per_s") if comp_ok else None,
            "compiled_status": _status(comp),
            "compiled_ratio": compiled_ratio,
        })
    return summary


# ------------------------------------------------------------------- table
#: per side of an entry: its value, status and baseline-RSS keys
_KEYS = {"vmas_ros": ("vmas_ros", "status", "vmas_ros_baseline_mb"), "compiled": ("compiled", "compiled_status", None),
         "peer": ("peer_value", "peer_status", "peer_baseline_mb")}


def _has_compiled(entries: Sequence[dict]) -> bool:
    """Any entry with a vmas_ros_compiled side (measured, skipped or failed): then the compiled columns show."""
    return any(e.get("compiled_status", "missing") != "missing" for e in entries)


def _value(entry: dict, side: str) -> str:
    """A median with its unit, or why there is none (a reason shared with vmas_ros is shown once)."""
    value_key, status_key, base_key = _KEYS[side]
    value, status = entry.get(value_key), entry.get(status_key, "missing")
    if value is None:
        if status in ("ok", "missing") or (side != "vmas_ros" and status == entry["status"]):
            return "-"
        return "omitted" if "omitted" in status else status
    if entry["unit"] == "MB":  # peak, and how much of it came after the imports
        base = entry.get(base_key) if base_key else None
        return f"{value:,.0f} MB" + ("" if base is None else f" (+{value - base:,.0f})")
    text = (f"{value:.3f}" if value < 100 else f"{value:,.1f}")
    return text + ("\\*" if side == "peer" and entry["peer_extrapolated"] else "")


def _ratio(entry: dict, key: str = "ratio") -> str:
    if entry.get(key) is None:
        return "-"
    return f"{entry[key]:.2f}x" + ("\\*" if entry["peer_extrapolated"] else "")


def _met(entry: dict, by_mode: bool = False) -> str:
    """The met? cell; ``by_mode`` (tables with compiled columns) adds which mode met the target."""
    if entry["target"] is None:
        return "-"
    if by_mode and entry["met"]:
        return "✓ met (eager)" if entry.get("met_by") == "eager" else "✓ met (compiled only)"
    return {True: "✓ met", False: "✗ not met", None: "n/a"}[entry["met"]]


def _header(head: List[str], left: Sequence[int]) -> List[str]:
    """A markdown header row and its alignment row (columns in ``left`` left-aligned, the rest right)."""
    return ["| " + " | ".join(head) + " |",
            "|" + "|".join("---" if i in left else "---:" for i in range(len(head))) + "|"]


def _main_table(entries: List[dict]) -> List[str]:
    compiled, default = _has_compiled(entries), any(e.get("default_mode") for e in entries)
    head = ["workload", "envs", "agents"] + (["default mode"] if default else [])
    head += ["vmas_ros ms/step", "VMAS ms/step", "ratio"] + (["first run s"] if default else [])
    head += ["compiled ms/step", "compiled ratio"] if compiled else []
    lines = _header(head + ["target", "met?"], left=(0, len(head) + 1))
    for e in entries:
        name = e["workload"] + (f" (vs {_LABEL.get(e['peer'], e['peer'])})" if e["peer"] != "vmas" else "")
        cells = [name, str(e["num_envs"]), "-" if e["n_agents"] is None else str(e["n_agents"])]
        cells += [e["vmas_ros_mode"] or "-"] if default else []
        cells += [_value(e, "vmas_ros"), _value(e, "peer"), _ratio(e)]
        if default:
            cells.append("-" if e.get("first_run_s") is None else f"{e['first_run_s']:.1f}")
        cells += [_value(e, "compiled"), _ratio(e, "compiled_ratio")] if compiled else []
        lines.append("| " + " | ".join(cells + [e["target"] or "-", _met(e, compiled)]) + " |")
    return lines


def _curve_table(workload: str, entries: List[dict]) -> List[str]:
    x, compiled = CURVES[workload], _has_compiled(entries)
    if x == "num_envs":
        head = ["num_envs", "vmas_ros ms/step", "VMAS ms/step", "vmas_ros env-steps/s", "VMAS env-steps/s", "speed-up"]
        head += ["compiled ms/step", "compiled env-steps/s", "compiled speed-up"] if compiled else []
    else:
        head = ["agents", "vmas_ros ms/step", "VMAS ms/step", "speed-up"]
        head += ["compiled ms/step", "compiled speed-up"] if compiled else []
    lines = [f"### {workload}", ""] + ([_LAYOUTS[workload][1], ""] if workload in _LAYOUTS else [])
    lines += _header(head, left=())
    for e in entries:
        cells = [str(e[x]), _value(e, "vmas_ros"), _value(e, "peer")]
        keys = ("vmas_ros_env_steps_per_s", "peer_env_steps_per_s") if x == "num_envs" else ()
        cells += ["-" if e[k] is None else f"{e[k]:,.0f}" for k in keys] + [_ratio(e)]
        if compiled:
            cells.append(_value(e, "compiled"))
            if x == "num_envs":
                cells.append("-" if e["compiled_env_steps_per_s"] is None else f"{e['compiled_env_steps_per_s']:,.0f}")
            cells.append(_ratio(e, "compiled_ratio"))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def format_suite_table(summary: Sequence[dict]) -> str:
    """The markdown report: one table of the workloads with targets, one per curve, and notes."""
    if not summary:
        return "(no results)"
    main = [e for e in summary if e["workload"] not in CURVES]
    lines: List[str] = _main_table(main) if main else []
    for workload in CURVES:
        entries = [e for e in summary if e["workload"] == workload]
        if entries:
            lines += ([""] if lines else []) + _curve_table(workload, entries)
    lines += ["", "ratio: peer median time / vmas_ros median time (speed-up) for step times; vmas_ros peak RSS / "
              "VMAS peak RSS for memory_30k (MB, each side in a fresh process; (+N): the part above the RSS "
              "after importing torch and the library). Sides alternate inside each repeat; ratios are of the "
              "medians of this run."]
    if _has_compiled(summary):
        lines.append("compiled: vmas_ros with its physics through torch.compile (--modes eager compiled), built like "
                     "the eager side and timed alternating with it and the peer; it compiles during the warm-up runs, "
                     "which are not timed. compiled ratio: peer median time / compiled median time. met?: the target "
                     "checked on the better of the two ratios: (eager) when the eager ratio meets it (also when both "
                     "do), (compiled only) when only the compiled one does. memory_30k is measured eager only.")
    elif any(e.get("default_mode") for e in summary):
        lines.append("default mode: vmas_ros as make_env builds it without flags; the default mode column says "
                     "whether that compiled the physics (torch.compile, during the untimed warm-up runs) or ran it "
                     "eagerly (above the size where the default mode compiles, the sphere worlds built with World, "
                     "or where no compiler works). first run s: the first, untimed run of the same steps on a "
                     "fresh env, compiling included (the latency a user meets once per env).")
    elif any(e.get("vmas_ros_mode") == "compiled" for e in summary):
        lines.append("vmas_ros ran compiled (--modes compiled: physics through torch.compile, compiled during the "
                     "warm-up runs); memory_30k is measured eager only.")
    if any(e["peer_extrapolated"] for e in summary):
        lines.append("\\* MPE was stepped for fewer envs (--mpe-max-envs) and its time scaled linearly.")
    omitted = sorted({e["n_agents"] for e in summary if e["peer_status"].startswith("skipped: omitted")})
    if omitted:
        lines.append(f"VMAS not run at {', '.join(map(str, omitted))} agents (--max-peer-agents): omitted, "
                     f"not extrapolated.")
    return "\n".join(lines)


# ------------------------------------------------------------------- plots
def _title(info: dict, what: str) -> str:
    threads = "/".join(map(str, info["threads"]))
    return (f"{what}\ntorch {info['torch']}, {threads} torch thread(s), {info['cpus_usable']} of "
            f"{info['cpu_count']} CPUs ({info.get('cpu_model') or 'CPU'}), {(info['date'] or '')[:10]}")


#: the agents plot's linear reference starts here: below, fixed costs per step hide the cost per agent
_LINEAR_FROM = 1_000


def _linear_reference(ax, ok: Sequence[dict], workloads: Sequence[str]) -> None:
    """A dashed line of cost proportional to the agents, through the largest point of the last
    measured curve's vmas_ros line (the swarm's when there is one), where a fixed cost per step
    matters least; drawn from ``_LINEAR_FROM`` agents on (over the whole curve when it has fewer than
    two points there)."""
    for workload in reversed(workloads):
        line = sorted((r for r in ok if r["workload"] == workload and r["side"] == "vmas_ros"),
                      key=lambda r: r["n_agents"])
        if line:
            break
    else:
        return
    x0, y0 = line[-1]["n_agents"], line[-1]["per_step_ms"]
    above = [r["n_agents"] for r in line if r["n_agents"] >= _LINEAR_FROM]
    xs = [above[0] if len(above) > 1 else line[0]["n_agents"], x0]
    if xs[0] == x0:  # one point: no slope to show
        return
    ax.plot(xs, [y0 * x / x0 for x in xs], linestyle="--", color="0.4", linewidth=1,
            label="linear cost (time ∝ agents)")


def _plot_curves(rows: Sequence[dict], workloads: Sequence[str], path: Path, info: dict) -> bool:
    """Log-log plot of curves sharing an x axis, every side, min-max of the repeats as bars; the
    agent curves with a linear-cost reference. False if nothing to plot."""
    x_key = CURVES[workloads[0]]
    ok = [r for r in rows if r["workload"] in workloads and r.get("status") == "ok"]
    if not ok:
        return False
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    colors = {"vmas_ros": "tab:green", COMPILED_SIDE: "tab:orange", "vmas": "tab:blue"}
    lines = {"scaling_agents_sparse": ("-.", "s")}  # (linestyle, marker); the rest solid with dots
    steps = ok[0]["steps"]
    fig, ax = plt.subplots(figsize=(8, 5), dpi=110)
    for workload in workloads:
        linestyle, marker = lines.get(workload, ("-", "o"))
        layout = f", {_LAYOUTS[workload][0]}" if workload in _LAYOUTS else ""
        for side in ("vmas_ros", COMPILED_SIDE, "vmas"):
            line = sorted((r for r in ok if r["workload"] == workload and r["side"] == side), key=lambda r: r[x_key])
            if not line:
                continue
            style = COMPILED_SIDE if side in OURS and all(r.get("compiled") for r in line) else side  # --modes compiled
            xs = [r[x_key] for r in line]
            if x_key == "num_envs":  # throughput: higher is better
                ys = [r["env_steps_per_s"] for r in line]
                low = [r["num_envs"] * steps / r["max_s"] for r in line]
                high = [r["num_envs"] * steps / r["min_s"] for r in line]
            else:
                ys = [r["per_step_ms"] for r in line]
                low = [r["min_s"] / steps * 1e3 for r in line]
                high = [r["max_s"] / steps * 1e3 for r in line]
            ax.plot(xs, ys, marker=marker, linestyle=linestyle, color=colors[style],
                    label=f"{_LABEL[style]} (CPU){layout}")
            ax.vlines(xs, low, high, color=colors[style], alpha=0.5)
    if x_key == "n_agents":
        _linear_reference(ax, ok, workloads)
    mine = [r for r in rows if r["workload"] in workloads]
    omitted = sorted({r[x_key] for r in mine if "omitted" in (r.get("note") or "")})
    if omitted:
        ax.plot([], [], linestyle="none",
                label=f"VMAS omitted at {', '.join(f'{n:,}' for n in omitted)} (not extrapolated)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ticks = sorted({r[x_key] for r in mine})
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:,.0f}"))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:,.4g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda value, _: ""))
    if x_key == "num_envs":
        ax.set_xlabel("number of parallel environments")
        ax.set_ylabel("env-steps per second")
        what = f"simple_spread throughput vs parallel envs ({steps} steps per run)"
    else:
        ax.set_xlabel("number of colliding sphere agents (1 env)")
        ax.set_ylabel("ms per World.step")
        layouts = " and ".join(_LAYOUTS[w][0] for w in workloads if any(r["workload"] == w for r in ok))
        what = f"World.step time vs agents, {layouts} spheres ({steps} steps per run)"
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize=8, title=f"bars: min-max of {ok[0]['repeats']} repeats", title_fontsize=8)
    ax.set_title(_title(info, what), fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return True


# ------------------------------------------------------------------- files
def measured_modes(rows: Sequence[dict]) -> List[str]:
    """The modes vmas_ros was run in (eager first), from the rows' ``compiled`` flags; memory
    rows are left out because memory is always eager, whatever the modes."""
    if any(r.get("default_mode") for r in rows):
        return ["default"]
    ours = [r for r in rows if r["side"] in OURS and r.get("metric") != "memory"]
    return [mode for mode, present in (("eager", any(not r.get("compiled") for r in ours)),
                                       ("compiled", any(r.get("compiled") for r in ours))) if present]


_MODES_LINE = {
    ("default",): "vmas_ros in the default mode, as make_env builds it without flags (`--modes default`, the "
                  "default), in its long run: the warm-up steps on through the default mode's switch to the compiled step "
                  "where that comes within 20,000 steps; the `default mode` column says how each point was timed.",
    ("eager",): "vmas_ros eager (no torch.compile).",
    ("compiled",): "vmas_ros compiled: physics through torch.compile (`--modes compiled`, or `--compile-physics`; "
                   "memory_30k eager).",
    ("eager", "compiled"): "vmas_ros measured in both modes, eager and compiled (physics through torch.compile), "
                           "timed side by side in every repeat (`--modes eager compiled`; memory_30k eager only).",
}


def write_suite_results(rows: Sequence[dict], out_dir, plot: bool = True) -> Dict[str, Path]:
    """Write ``suite.csv`` (one row per workload point and side, every repeat), ``suite.json``
    (rows, summary, machine info), ``suite.md`` and, with ``plot``, the PNGs of :data:`PLOTS`
    whose curves were measured (``suite_agents.png``: both agent curves on one pair of axes).
    Returns the paths by kind."""
    out, rows, info, paths = start_results(rows, out_dir, "suite", SUITE_COLUMNS)
    summary = summarize(rows)
    notes = [
        "Timed: steps calls of env.step (World.step for the sphere worlds: spheres_100, swarm_N, scaling_agents "
        "and scaling_agents_sparse); building, the reset before each repeat and the random actions (one seeded "
        "generator, shared by both sides) are not.",
        "navigation_swarm_N: vmas_ros takes each step's actions stacked in one [n_agents, num_envs, size] tensor, "
        "VMAS the same values as its list of per-agent tensors.",
        "Sides alternate inside every repeat; ratios are of the medians of this run.",
        "memory_30k: peak RSS of a fresh python process per side and repeat (torch + that library only); "
        "baseline_rss_mb is its RSS after the imports. For the other rows peak_rss_mb is this process's "
        "high-water mark when the point ended, both sides together.",
        "mpe_1k: MPE (mpe2) steps one env at a time, as in the VMAS paper; vmas_ros uses its own random actions.",
        "Default mode (default_mode=true): vmas_ros built as make_env builds it without flags; compiled says "
        "whether that compiled the physics.",
        "Modes: compiled rows (compiled=true) ran vmas_ros's physics through torch.compile, compiled during the "
        "untimed warm-up runs; with both modes their side is vmas_ros_compiled. memory_30k is measured eager only.",
    ]
    modes = measured_modes(rows)
    document = {"benchmark": "suite", "machine": info, "modes": modes,
                "targets": {k: list(v) for k, v in TARGETS.items()}, "notes": notes, "rows": rows, "summary": summary}
    header = ("# Benchmark suite: vmas_ros vs VMAS 1.5.2\n\n"
              + f"Modes measured: {', '.join(modes) or 'none'}. "
              + _MODES_LINE.get(tuple(modes), "") + "\n\n"
              + _title(info, f"{'/'.join(map(str, sorted({r['steps'] for r in rows})))} steps per run").replace(
                  "\n", ". ") + "\n\n")
    finish_results(paths, document, header + format_suite_table(summary))
    if plot:
        for kind, (name, workloads) in PLOTS.items():
            if _plot_curves(rows, workloads, out / name, info):
                paths[kind] = out / name
    return paths
