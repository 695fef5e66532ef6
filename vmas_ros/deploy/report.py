"""The engine's and the fleet's episodes side by side: one row per episode, then the totals.

The rows pair episode ``k`` of the engine with the fleet's episode that
started from the same state (the fleet's ``plan_index``). Coverage is
compared as the ratio fleet / engine (1 means the policy does as well on the
fleet); with one goal per robot, success is every robot within the goal
radius at once before the episode's end (navigation's ``done``), and time to
goal is when that first happened.
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional

#: the fleet parameters a table states: the conditions the policy met on the fleet
CONDITIONS = ("drive", "use_stamped_cmd_vel", "command_latency", "velocity_lag", "odom_noise_position",
              "odom_noise_yaw", "odom_noise_velocity", "max_linear_speed", "max_angular_speed", "scan_rays",
              "scan_rate_hz", "end_on_goals")


#: beyond this many episodes the plot numbers them instead of naming each
MAX_LABELLED = 20


def _mean(values: List[Optional[float]]) -> Optional[float]:
    kept = [v for v in values if v is not None]
    return sum(kept) / len(kept) if kept else None


def _fmt(value: Optional[float], digits: int = 3) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def pair_episodes(engine: Dict[str, Any], fleet: Dict[str, Any], labels: List[str]) -> List[Dict[str, Any]]:
    """One row per episode: ``label``, and the engine's and the fleet's metrics."""
    by_plan = {e["plan_index"]: e for e in fleet["episodes"] if e["ended_by"] != "shutdown"}
    rows = []
    for k, (label, ours) in enumerate(zip(labels, engine["episodes"])):
        theirs = by_plan[k]
        row = {"episode": label, "engine_coverage": ours["coverage"], "fleet_coverage": theirs["coverage"],
               "engine_collisions": ours["robot_robot"], "fleet_collisions": theirs["collisions"]["robot_robot"]}
        if engine["per_robot_goals"]:
            row.update(engine_time=ours["all_at_goal_time"], fleet_time=theirs["all_at_goal_time"])
        rows.append(row)
    return rows


def totals(rows: List[Dict[str, Any]], per_robot_goals: bool) -> Dict[str, Any]:
    """Means over the episodes, the coverage ratio of the means, success rates and collisions per episode."""
    found: Dict[str, Any] = {"episodes": len(rows)}
    engine, fleet = _mean([r["engine_coverage"] for r in rows]), _mean([r["fleet_coverage"] for r in rows])
    found.update(engine_coverage=engine, fleet_coverage=fleet,
                 coverage_ratio=(fleet / engine) if engine and fleet is not None else None)
    for side in ("engine", "fleet"):
        found[f"{side}_collisions_per_episode"] = sum(r[f"{side}_collisions"] for r in rows) / max(len(rows), 1)
        if per_robot_goals:
            times = [r[f"{side}_time"] for r in rows]
            found[f"{side}_success_rate"] = sum(t is not None for t in times) / max(len(rows), 1)
            found[f"{side}_time_to_goal"] = _mean(times)
    return found


def markdown(rows: List[Dict[str, Any]], summary: Dict[str, Any], per_robot_goals: bool,
             heading: Dict[str, Any]) -> str:
    """The report as Markdown: what ran, the per-episode table, the totals."""
    lines = [f"- policy: `{heading['policy']}` ({heading['scenario']}, kwargs `{heading['scenario_kwargs']}`)",
             f"- command: `{heading['command']}`",
             "- fleet: " + ", ".join(f"{k} {heading['fleet'][k]}" for k in CONDITIONS if k in heading["fleet"]),
             f"- policy_node acts on: {heading.get('act_on', 'timer')}; parameters: {heading['policy_node']}"]
    lines += scan_lines(heading)
    lines.append("")
    columns = ["episode", "engine coverage (m)", "fleet coverage (m)", "ratio"]
    if per_robot_goals:
        columns += ["engine done at (s)", "fleet done at (s)"]
    columns += ["engine collisions", "fleet collisions"]
    lines += ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        ratio = (r["fleet_coverage"] / r["engine_coverage"]) if r["engine_coverage"] and r["fleet_coverage"] is not None \
            else None
        cells = [r["episode"], _fmt(r["engine_coverage"]), _fmt(r["fleet_coverage"]), _fmt(ratio, 2)]
        if per_robot_goals:
            cells += [_fmt(r["engine_time"], 1) if r["engine_time"] is not None else "never",
                      _fmt(r["fleet_time"], 1) if r["fleet_time"] is not None else "never"]
        cells += [str(r["engine_collisions"]), str(r["fleet_collisions"])]
        lines.append("| " + " | ".join(cells) + " |")
    s = summary
    lines += ["", f"Mean coverage: engine {_fmt(s['engine_coverage'])} m, fleet {_fmt(s['fleet_coverage'])} m, "
                  f"ratio {_fmt(s['coverage_ratio'], 2)}."]
    if per_robot_goals:
        lines.append(f"Success (all robots on their goals at once): engine {s['engine_success_rate']:.0%}, "
                     f"fleet {s['fleet_success_rate']:.0%}; mean time to done: engine "
                     f"{_fmt(s['engine_time_to_goal'], 1)} s, fleet {_fmt(s['fleet_time_to_goal'], 1)} s.")
    lines.append(f"Collisions per episode: engine {s['engine_collisions_per_episode']:.2f}, "
                 f"fleet {s['fleet_collisions_per_episode']:.2f}.")
    return "\n".join(lines) + "\n"


def scan_lines(found: Dict[str, Any]) -> List[str]:
    """The report lines that state the navigation adapter's scan margin and lead of the fleet run (from
    ``found``'s ``scan_margin`` and ``scan_lead``; none for an adapter without them)."""
    lines = []
    if found.get("scan_margin") is not None:
        lines.append(f"- scan margin: {found['scan_margin']:g} m (the navigation adapter's scan_margin: scan "
                     f"returns read that much closer)")
    if found.get("scan_lead") is not None:
        lines.append(f"- scan lead: {found['scan_lead']:g} s (the navigation adapter's scan_lead: each ray also "
                     f"read closer by the robot's speed towards it times this)")
    return lines


def scan_note(found: Dict[str, Any]) -> str:
    """The plots' title note for the scan margin and lead (``found`` as for :func:`scan_lines`), or ''."""
    parts = []
    if found.get("scan_margin") is not None:
        parts.append(f"scan margin {found['scan_margin']:g} m")
    if found.get("scan_lead"):
        parts.append(f"scan lead {found['scan_lead']:g} s")
    return "".join(f", {part}" for part in parts)


def plot(rows: List[Dict[str, Any]], per_robot_goals: bool, path, title: str) -> bool:
    """Coverage (and time to done) per episode, engine beside fleet, as a PNG; False without matplotlib."""
    plt = pyplot()
    if plt is None:
        return False
    panels = 2 if per_robot_goals else 1
    figure, axes = plt.subplots(1, panels, figsize=(5.5 * panels, 3.6), squeeze=False)
    x = list(range(len(rows)))
    width = 0.4
    series = [("coverage (m)", "engine_coverage", "fleet_coverage")]
    if per_robot_goals:
        series.append(("time to done (s); missing: never", "engine_time", "fleet_time"))
    for axis, (label, ours, theirs) in zip(axes[0], series):
        values = [[r[key] if r[key] is not None else math.nan for r in rows] for key in (ours, theirs)]
        axis.bar([i - width / 2 for i in x], values[0], width, label="engine")
        axis.bar([i + width / 2 for i in x], values[1], width, label="robot_fleet")
        if len(rows) <= MAX_LABELLED:
            axis.set_xticks(x, [r["episode"] for r in rows], rotation=45, ha="right", fontsize=7)
        else:  # names would overlap: number the episodes in the table's order
            axis.set_xlabel("episode (the report's rows, in order)")
        axis.set_ylabel(label)
        axis.legend(fontsize=8)
    save(figure, title, path)
    return True


def pyplot():
    """matplotlib's pyplot on the file-only Agg backend; None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def save(figure, title: str, path) -> None:
    """Title, lay out, write and close a figure (the deploy reports' PNGs)."""
    import matplotlib.pyplot as plt

    figure.suptitle(title, fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
