"""The benchmark suite's swarm workloads: sphere swarms (``swarm_N``), the agent
curve in the swarm layout (``scaling_agents_sparse``, plotted with the overlapping
curve and a linear-cost reference) and navigation swarms stepped with stacked
actions (``navigation_swarm_N``).

The big sizes are only planned, never built: what runs uses a handful of agents
(:func:`vmas_ros.bench.suite.navigation_swarm` builds the same workload at any size).
"""
from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from vmas_ros.bench import suite
from vmas_ros.bench import suite_cases
from vmas_ros.bench.suite_report import CURVES, PLOTS, write_suite_results

HAS_VMAS = "vmas" in suite._mpe.available_peers()


# ------------------------------------------------------------ sphere swarms
def test_swarm_workloads_are_sparse_sphere_worlds_without_the_peer_above_the_cap():
    for n in (1_000, 10_000, 100_000):
        workload = suite.WORKLOADS[f"swarm_{n}"]
        assert (workload.kind, workload.num_envs, workload.n_agents, workload.spacing) == ("spheres", 1, n, 0.5)
        assert workload.settle, "swarms time the steady state: one untimed step after the start"
    assert not suite.WORKLOADS["spheres_100"].settle
    (unit,) = suite.plan_suite(["swarm_1000"], peers=["vmas"], max_peer_agents=100)
    assert unit.sides == ["vmas_ros"] and "max-peer-agents 100" in unit.skipped["vmas"]
    (small,) = suite.plan_suite(["swarm_1000"], peers=["vmas"], max_peer_agents=1_000)
    assert "vmas" not in small.skipped or "not installed" in small.skipped["vmas"]


def test_a_settled_sphere_case_steps_once_in_its_untimed_set_up(monkeypatch):
    from vmas_ros.bench.suite_cases import spheres_case
    from vmas_ros.simulator.core import World

    steps = []
    step = World.step
    monkeypatch.setattr(World, "step", lambda self: (steps.append(self), step(self))[1])
    for settle, untimed in ((True, 1), (False, 0)):
        steps.clear()
        case = spheres_case("vmas_ros", 8, 1, 3, 0, settle=settle)  # builds, then sets up once
        assert len(steps) == untimed
        case.setup()
        case.run()
        assert len(steps) == 2 * untimed + 3


# ------------------------------------------------------- the sparse curve
def _points(units, name):
    return [(u.n_agents, u.sides, u.skipped) for u in units if u.workload.name == name]


def test_sparse_curve_is_the_swarm_layout_with_its_own_points_to_100k():
    sparse, dense = suite.WORKLOADS["scaling_agents_sparse"], suite.WORKLOADS["scaling_agents"]
    assert (sparse.kind, sparse.num_envs, sparse.spacing, sparse.settle) == ("agents_curve", 1, 0.5, True)
    assert (dense.spacing, dense.settle) == (suite_cases.SPHERE_SPACING, False)
    assert max(sparse.points) == 100_000 and min(sparse.points) <= 1_000 and len(sparse.points) >= 5
    assert CURVES["scaling_agents_sparse"] == "n_agents"
    assert PLOTS["agents_png"][1] == ("scaling_agents", "scaling_agents_sparse")

    units = suite.plan_suite(["scaling_agents", "scaling_agents_sparse"], peers=["vmas"], max_peer_agents=100)
    assert [n for n, _, _ in _points(units, "scaling_agents")] == list(suite.CURVE_AGENTS)
    planned = _points(units, "scaling_agents_sparse")
    assert [n for n, _, _ in planned] == sorted(suite.CURVE_AGENTS_SPARSE)
    assert all(u.num_envs == 1 for u in units)
    for n, sides, skipped in planned:  # VMAS only up to the cap, as on the dense curve
        if n > 100:
            assert sides == ["vmas_ros"] and "above --max-peer-agents 100" in skipped["vmas"]
        else:
            assert "vmas" in sides or "not installed" in skipped["vmas"]

    # each curve has its own option; one does not move the other
    units = suite.plan_suite(["scaling_agents", "scaling_agents_sparse"], curve_agents_sparse=[9, 3, 9])
    assert [n for n, _, _ in _points(units, "scaling_agents_sparse")] == [3, 9]
    assert [n for n, _, _ in _points(units, "scaling_agents")] == list(suite.CURVE_AGENTS)


def test_sparse_curve_times_a_settled_swarm(monkeypatch):
    seen = []

    def spheres(side, n_agents, num_envs, steps, seed, compiled=False, **layout):
        seen.append((side, n_agents, layout))
        return suite_cases.spheres_case(side, n_agents, num_envs, steps, seed, compiled, **layout)

    monkeypatch.setattr(suite, "_spheres_case", spheres)
    rows = suite.run_suite(["scaling_agents_sparse"], curve_agents_sparse=[3], steps=1, repeats=1, warmup=0,
                           threads=1, peers=[], progress=False)
    assert [(r["workload"], r["n_agents"], r["side"], r["status"]) for r in rows] == [
        ("scaling_agents_sparse", 3, "vmas_ros", "ok"), ("scaling_agents_sparse", 3, "vmas", "skipped")]
    assert seen == [("vmas_ros", 3, {"spacing": suite_cases.SWARM_SPACING, "settle": True})]


def _curve_rows():
    """Both agent curves, made up: the overlapping one quadratic in the agents, the swarm linear."""
    rows = []
    for workload, counts, cost in (("scaling_agents", (10, 100, 1_000), lambda n: 0.1 + 1e-5 * n * n),
                                   ("scaling_agents_sparse", (100, 1_000, 10_000, 100_000), lambda n: 0.2 + 1e-3 * n)):
        for n in counts:
            for side, factor in (("vmas_ros", 1.0), ("vmas", 20.0)):
                ms = cost(n) * factor
                note = "omitted: above --max-peer-agents 100" if side == "vmas" and n > 100 else ""
                row = {"run_id": "r", "workload": workload, "side": side, "num_envs": 1, "n_agents": n,
                       "metric": "time", "device": "cpu", "threads": 1, "steps": 10, "repeats": 3, "compiled": False,
                       "status": "skipped" if note else "ok", "note": note, "extrapolated": False}
                if not note:
                    row.update(median_s=ms / 100, min_s=ms / 110, max_s=ms / 90, times_s=[ms / 100] * 3, value=ms,
                               per_step_ms=ms, unit="ms/step")
                rows.append(row)
    return rows


def test_agents_plot_has_both_curves_and_a_linear_reference(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    drawn = {}
    save = Figure.savefig

    def keep(figure, path, *args, **kwargs):
        (ax,) = figure.axes
        drawn[path.name] = {line.get_label(): (list(line.get_xdata()), list(line.get_ydata()), line.get_linestyle())
                            for line in ax.get_lines()}
        return save(figure, path, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    paths = write_suite_results(_curve_rows(), tmp_path)
    assert paths["agents_png"].stat().st_size > 0 and "envs_png" not in paths
    lines = drawn["suite_agents.png"]
    dense_x, _, dense_style = lines["vmas_ros (CPU), overlapping"]
    sparse_x, sparse_y, sparse_style = lines["vmas_ros (CPU), swarm"]
    assert dense_x == [10, 100, 1_000] and sparse_x == [100, 1_000, 10_000, 100_000] and dense_style != sparse_style
    assert lines["VMAS (CPU), overlapping"][0] == [10, 100] and lines["VMAS (CPU), swarm"][0] == [100]
    xs, ys, style = lines["linear cost (time ∝ agents)"]
    assert style == "--" and xs == [1_000, 100_000]  # from 1,000 agents, through the swarm's largest point
    assert ys[1] == pytest.approx(sparse_y[-1]) and ys[0] / ys[1] == pytest.approx(xs[0] / xs[1])
    assert any("VMAS omitted at 1,000, 10,000, 100,000" in label for label in lines)
    text = paths["md"].read_text()
    assert text.index("### scaling_agents\n") < text.index("### scaling_agents_sparse\n")
    assert "| 100000 | 100.2 | omitted | - |" in text


def test_the_linear_reference_spans_a_curve_that_stays_below_1000_agents(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    labels = {}
    monkeypatch.setattr(Figure, "savefig", lambda figure, path, *a, **k: labels.update(
        {line.get_label(): list(line.get_xdata()) for line in figure.axes[0].get_lines()}))
    write_suite_results([r for r in _curve_rows() if r["workload"] == "scaling_agents"], tmp_path)
    assert labels["linear cost (time ∝ agents)"] == [10, 1_000]  # one point above 1,000: the whole curve


# ------------------------------------------------------ navigation swarms
def test_navigation_swarms_are_stacked_env_workloads_in_the_swarm_layout():
    for n in (1_000, 10_000):
        workload = suite.WORKLOADS[f"navigation_swarm_{n}"]
        assert workload == suite.navigation_swarm(n)
        assert (workload.kind, workload.scenario, workload.num_envs, workload.stacked_actions) == (
            "env", "navigation", 1, True)
        kwargs = dict(workload.kwargs)
        half = 0.25 * math.sqrt(n)
        assert kwargs == {"n_agents": n, "agent_radius": 0.05, "world_spawning_x": pytest.approx(half),
                          "world_spawning_y": pytest.approx(half)}  # collisions and the lidar stay default
    assert not any(w.stacked_actions for name, w in suite.WORKLOADS.items() if not name.startswith("navigation_"))
    units = suite.plan_suite(["navigation_swarm_1000", "navigation_swarm_10000"], peers=["vmas"])
    assert [(u.n_agents, u.sides) for u in units] == [(1_000, ["vmas_ros"]), (10_000, ["vmas_ros"])]
    assert all("above --max-peer-agents 100" in u.skipped["vmas"] for u in units)


@pytest.mark.parametrize("stacked", [True, False])
def test_vmas_ros_gets_the_actions_stacked_and_the_peer_the_same_values_as_a_list(monkeypatch, stacked):
    received = {}
    make = suite_cases._make_env

    def recording(side, *args, **kwargs):
        env = make(side, *args, **kwargs)
        step = env.step
        received[side] = []
        env.step = lambda action: (received[side].append(action), step(action))[1]
        return env

    monkeypatch.setattr(suite_cases, "_make_env", recording)
    workload = dataclasses.replace(suite.navigation_swarm(4), stacked_actions=stacked)
    sides = ["vmas_ros"] + (["vmas"] if HAS_VMAS else [])
    unit = suite.Unit(workload, 1, 4, sides, {})
    cases = suite_cases.env_cases(unit, steps=3, seed=0)
    for case in cases.values():
        case.setup()
        case.run()
    ours = received["vmas_ros"]
    assert len(ours) == 3
    if stacked:
        assert all(isinstance(a, torch.Tensor) and a.shape == (4, 1, 2) for a in ours)
    else:
        assert all(isinstance(a, list) and len(a) == 4 for a in ours)
    if HAS_VMAS:  # the peer: always the list, of the same values
        theirs = received["vmas"]
        assert all(isinstance(a, list) and [t.shape for t in a] == [(1, 2)] * 4 for a in theirs)
        for mine, peer in zip(ours, theirs):
            assert torch.equal(mine if stacked else torch.stack(mine), torch.stack(peer))


def test_a_tiny_navigation_swarm_runs_through_the_suite(monkeypatch):
    monkeypatch.setitem(suite.WORKLOADS, "navigation_swarm_4", suite.navigation_swarm(4))
    rows = suite.run_suite(["navigation_swarm_4"], steps=2, repeats=1, warmup=0, threads=1, progress=False,
                           peers=["vmas"], max_peer_agents=2)
    assert [(r["side"], r["status"], r["n_agents"], r["scenario"]) for r in rows] == [
        ("vmas_ros", "ok", 4, "navigation"), ("vmas", "skipped", 4, "navigation")]
    assert "above --max-peer-agents 2" in rows[1]["note"] or "not installed" in rows[1]["note"]
