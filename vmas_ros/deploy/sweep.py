"""``deploy-eval --latency-sweep``: the same episodes on robot_fleet at several command latencies.

The engine runs once; the fleet runs once per latency, each run in a
subfolder of its own (``latency_050ms/``) with the full report of a single
deploy-eval. The sweep's own files put the runs together, one row per
latency: ``sweep.json``, ``sweep.md`` and ``sweep.png`` (success and
collisions against latency, the engine's success and 90% of it drawn as
lines). ``tolerated`` names the first latency at which the fleet's success
falls below ``KEEP`` of the engine's: where the policy stops transferring.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from vmas_ros.deploy import report

__all__ = ["KEEP", "parse_latencies", "folder_name", "sweep_rows", "first_below", "run_sweep"]

#: the share of the engine's success rate the fleet must keep (docs/bench/deploy.md)
KEEP = 0.9
#: a latency beyond this is a unit mistake (ms given as s): robot_fleet refuses more than 10 s
MAX_LATENCY_S = 10.0


def parse_latencies(text: str) -> List[float]:
    """``'0,0.05,0.1'`` -> [0.0, 0.05, 0.1]: seconds, each in [0, 10], in increasing order, none repeated."""
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        raise ValueError(f"--latency-sweep must be seconds separated by commas like '0,0.05,0.1', got {text!r}") \
            from None
    bad = [v for v in values if not (math.isfinite(v) and 0.0 <= v <= MAX_LATENCY_S)]
    if bad:
        raise ValueError(f"--latency-sweep latencies must be seconds in [0, {MAX_LATENCY_S:g}], got {bad[0]!r} "
                         f"(in {text!r})")
    if values != sorted(set(values)):
        raise ValueError(f"--latency-sweep latencies must increase with none repeated, got {text!r}")
    return values


def folder_name(latency: float) -> str:
    """The subfolder of one latency's run: ``latency_050ms``."""
    return f"latency_{round(latency * 1000):03d}ms"


def sweep_rows(results: List[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """One row per ``{"latency", "totals"}`` result: success rates, their ratio, time to done, collisions."""
    rows = []
    for result in results:
        totals = result["totals"]
        engine, fleet = totals.get("engine_success_rate"), totals.get("fleet_success_rate")
        rows.append({"latency": result["latency"], "episodes": totals["episodes"], "engine_success": engine,
                     "fleet_success": fleet,
                     "success_ratio": (fleet / engine) if engine and fleet is not None else None,
                     "engine_time_to_goal": totals.get("engine_time_to_goal"),
                     "fleet_time_to_goal": totals.get("fleet_time_to_goal"),
                     "engine_collisions": totals["engine_collisions_per_episode"],
                     "fleet_collisions": totals["fleet_collisions_per_episode"],
                     "coverage_ratio": totals.get("coverage_ratio")})
    return rows


def first_below(rows: List[Dict[str, Any]], keep: float = KEEP) -> Optional[float]:
    """The first latency at which the fleet's success is below ``keep`` x the engine's; None if it never is."""
    for row in rows:
        if row["success_ratio"] is not None and row["success_ratio"] < keep:
            return row["latency"]
    return None


def _cell(value: Optional[float], form: str) -> str:
    return "n/a" if value is None else format(value, form)


def markdown(rows: List[Dict[str, Any]], policy: str, command: str, act_on: str = "timer",
             scan: Optional[Dict[str, Any]] = None) -> str:
    lines = [f"- policy: `{policy}`", f"- command: `{command}`", f"- policy_node acts on: {act_on}"]
    lines += report.scan_lines(scan or {})
    lines += ["",
             "| latency (ms) | episodes | engine success | fleet success | fleet / engine | engine done at (s) | "
             "fleet done at (s) | engine collisions / episode | fleet collisions / episode |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['latency'] * 1000:.0f} | {r['episodes']} | {_cell(r['engine_success'], '.0%')} | "
                     f"{_cell(r['fleet_success'], '.0%')} | {_cell(r['success_ratio'], '.2f')} | "
                     f"{_cell(r['engine_time_to_goal'], '.1f')} | {_cell(r['fleet_time_to_goal'], '.1f')} | "
                     f"{r['engine_collisions']:.2f} | {r['fleet_collisions']:.2f} |")
    below = first_below(rows)
    lines += ["", f"The fleet's success falls below {KEEP:.0%} of the engine's at {below * 1000:.0f} ms."
              if below is not None else
              f"The fleet's success stays at or above {KEEP:.0%} of the engine's up to "
              f"{rows[-1]['latency'] * 1000:.0f} ms."]
    return "\n".join(lines) + "\n"


def plot(rows: List[Dict[str, Any]], path: Path, title: str) -> bool:
    """Success and collisions against latency as a PNG; False without matplotlib."""
    plt = report.pyplot()
    if plt is None:
        return False
    ms = [r["latency"] * 1000 for r in rows]
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    engine = rows[0]["engine_success"]
    left.plot(ms, [r["fleet_success"] for r in rows], "o-", label="robot_fleet")
    if engine is not None:
        left.axhline(engine, color="C1", label="engine")
        left.axhline(KEEP * engine, color="C1", linestyle="--", label=f"{KEEP:.0%} of the engine's")
    left.set(xlabel="command latency (ms)", ylabel="success rate", ylim=(0, 1.05))
    left.legend(fontsize=8)
    right.plot(ms, [r["fleet_collisions"] for r in rows], "o-", label="robot_fleet")
    right.axhline(rows[0]["engine_collisions"], color="C1", label="engine")
    right.set(xlabel="command latency (ms)", ylabel="collisions per episode")
    right.legend(fontsize=8)
    report.save(figure, title, path)
    return True


def run_sweep(out: Path, latencies: List[float], fleet_report: Callable[[Path, float], Dict[str, Any]],
              policy: str, command: str, per_robot_goals: bool, act_on: str = "timer",
              scan: Optional[Dict[str, Any]] = None) -> str:
    """Run ``fleet_report(folder, latency)`` per latency, then write the sweep's files; returns its Markdown.

    ``act_on``: policy_node's ``act_on`` in every run, stated in the files; so are ``scan``'s
    ``scan_margin`` and ``scan_lead``, the navigation adapter's (None: an adapter without them).
    """
    if not per_robot_goals:
        raise ValueError("--latency-sweep measures success (every robot on its own goal): the policy's scenario has "
                         "no goal per robot")
    results = []
    for latency in latencies:
        folder = out / folder_name(latency)
        folder.mkdir(parents=True, exist_ok=True)
        results.append({"latency": latency, "totals": fleet_report(folder, latency)})
    rows = sweep_rows(results)
    below = first_below(rows)
    (out / "sweep.json").write_text(json.dumps({"policy": policy, "command": command, "act_on": act_on,
                                                **(scan or {}), "keep": KEEP, "first_below": below,
                                                "rows": rows}, indent=1))
    text = markdown(rows, policy, command, act_on, scan)
    (out / "sweep.md").write_text(text)
    plot(rows, out / "sweep.png", f"{Path(policy).name}: success on robot_fleet against command latency")
    return text
