"""The benchmark suite (``vmas-ros bench suite``): files, columns, ratios, targets,
skipped workloads and option errors.

The suite really runs once, at a tiny scale, through the command line, and once
more with both modes (eager and compiled: slow, it compiles); every other check
reuses the first run, runs one tiny workload or feeds made-up rows to the report. Benchmarks are
measurements, not timed tests: nothing here asserts on speed.
"""
from __future__ import annotations

import csv
import json
import statistics

import logging

import numpy as np
import pytest
import torch
from PIL import Image

import vmas_ros
from vmas_ros.bench.cli import parse_bench_args
from vmas_ros.bench import cli as bench_cli
from vmas_ros.bench import suite
from vmas_ros.bench.suite_report import (
    SUITE_COLUMNS,
    TARGETS,
    evaluate_target,
    format_suite_table,
    summarize,
    write_suite_results,
)

HAS_VMAS = "vmas" in suite._mpe.available_peers()
HAS_MPE = "mpe" in suite._mpe.available_peers()
RUN = ["spread_1k", "scaling_envs", "scaling_agents", "scaling_agents_sparse", "memory_30k", "mpe_1k", "discovery_1k"]
ARGV = ["suite", "--workloads", *RUN, "--scale", "0.002", "--steps", "2", "--repeats", "1", "--threads", "1",
        "--curve-agents", "2", "4", "--curve-agents-sparse", "3", "6", "--max-peer-agents", "2", "--mpe-max-envs", "1",
        "--no-progress"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One real run of the command (skipping discovery_1k even once it is registered)."""
    pytest.importorskip("matplotlib")
    out = tmp_path_factory.mktemp("suite")
    patch = pytest.MonkeyPatch()
    real = suite._scenario_available
    patch.setattr(suite, "_scenario_available", lambda name: name != "discovery" and real(name))
    try:
        code = bench_cli.run_bench_command(parse_bench_args(ARGV + ["--out", str(out)]))
    finally:
        patch.undo()
    document = json.loads((out / "suite.json").read_text())
    return code, out, document


def _rows(document, workload):
    return [r for r in document["rows"] if r["workload"] == workload]


def test_command_writes_every_file(run):
    code, out, document = run
    assert code == 0
    for name in ("suite.csv", "suite.json", "suite.md", "suite_envs.png", "suite_agents.png"):
        assert (out / name).stat().st_size > 0, name
    for name in ("suite_envs.png", "suite_agents.png"):
        with Image.open(out / name) as image:
            pixels = np.asarray(image.convert("RGB"))
        colours = np.unique(pixels[::4, ::4].reshape(-1, 3), axis=0)
        assert pixels.shape[0] > 100 and len(colours) > 10, f"{name} is blank"
    machine = document["machine"]
    assert machine["torch"] == torch.__version__ and machine["threads"] == [1] and machine["cpu_count"] >= 1


def test_csv_has_the_columns_and_one_line_per_row(run):
    _, out, document = run
    with open(out / "suite.csv", newline="") as handle:
        reader = csv.DictReader(handle)
        lines = list(reader)
    assert reader.fieldnames == SUITE_COLUMNS
    assert [(line["workload"], line["side"]) for line in lines] == [
        (r["workload"], r["side"]) for r in document["rows"]]
    assert {line["workload"] for line in lines} == set(RUN)


def test_measured_rows_are_consistent(run):
    _, _, document = run
    ok = [r for r in document["rows"] if r["status"] == "ok"]
    assert {r["side"] for r in ok} >= {"vmas_ros"} | ({"vmas"} if HAS_VMAS else set())
    for row in ok:
        assert row["steps"] == 2 and row["repeats"] == 1 and row["threads"] == 1
        assert row["median_s"] == pytest.approx(statistics.median(row["times_s"]))
        if row["metric"] == "time":
            assert row["value"] == pytest.approx(row["median_s"] / 2 * 1e3) and row["unit"] == "ms/step"
    assert [r["num_envs"] for r in _rows(document, "spread_1k")] == [2] * len(_rows(document, "spread_1k"))
    assert sorted({r["num_envs"] for r in _rows(document, "scaling_envs")}) == [1, 2, 20, 60]  # scaled, min 1
    memory = _rows(document, "memory_30k")
    assert [r["side"] for r in memory] == ["vmas_ros"] + (["vmas"] if HAS_VMAS else [])
    for row in memory:
        assert row["unit"] == "MB" and row["num_envs"] == 60 and len(row["rss_mb"]) == 1
        assert row["value"] == row["rss_mb"][0] >= row["baseline_rss_mb"] > 0


def test_ratios_are_the_ratio_of_the_medians(run):
    _, _, document = run
    assert document["summary"] == json.loads(json.dumps(summarize(document["rows"])))
    checked = 0
    for entry in document["summary"]:
        pair = [r for r in document["rows"] if r["workload"] == entry["workload"]
                and r["num_envs"] == entry["num_envs"] and r["n_agents"] == entry["n_agents"]]
        ours = next(r for r in pair if r["side"] == "vmas_ros")
        theirs = next((r for r in pair if r["side"] != "vmas_ros" and r["status"] == "ok"), None)
        if entry["ratio"] is None:
            continue
        expected = (ours["value"] / theirs["value"] if entry["metric"] == "memory"
                    else theirs["median_s"] / ours["median_s"])
        assert entry["ratio"] == pytest.approx(expected)
        checked += 1
    assert checked >= (6 if HAS_VMAS else 0)


def test_mpe_above_the_cap_is_extrapolated(run):
    _, _, document = run
    rows = _rows(document, "mpe_1k")
    if not HAS_MPE:
        pytest.fail("mpe2 is a test dependency of the benchmarks")
    (mpe_row,) = [r for r in rows if r["side"] == "mpe"]
    assert mpe_row["num_envs"] == 2 and mpe_row["measured_envs"] == 1 and mpe_row["extrapolated"] is True
    (entry,) = [e for e in document["summary"] if e["workload"] == "mpe_1k"]
    assert entry["peer"] == "mpe" and entry["peer_extrapolated"] is True and entry["target"] == ">= 300x"


def test_peer_above_max_peer_agents_is_omitted_not_extrapolated(run):
    _, out, document = run
    rows = _rows(document, "scaling_agents")
    by = {(r["n_agents"], r["side"]): r for r in rows}
    assert by[(2, "vmas_ros")]["status"] == by[(4, "vmas_ros")]["status"] == "ok"
    if HAS_VMAS:
        assert by[(2, "vmas")]["status"] == "ok"
    assert by[(4, "vmas")]["status"] == "skipped" and "max-peer-agents 2" in by[(4, "vmas")]["note"]
    assert by[(4, "vmas")].get("median_s") is None
    sparse = {(r["n_agents"], r["side"]): r["status"] for r in _rows(document, "scaling_agents_sparse")}
    assert sparse == {(3, "vmas_ros"): "ok", (3, "vmas"): "skipped", (6, "vmas_ros"): "ok", (6, "vmas"): "skipped"}
    assert "VMAS not run at 3, 4, 6 agents" in (out / "suite.md").read_text()


def test_unavailable_scenario_is_reported_as_skipped(run):
    _, out, document = run
    rows = _rows(document, "discovery_1k")
    assert {r["side"]: (r["status"], r["note"]) for r in rows} == {
        "vmas_ros": ("skipped", "scenario not available"), "vmas": ("skipped", "scenario not available")}
    (line,) = [line for line in (out / "suite.md").read_text().splitlines() if line.startswith("| discovery_1k")]
    assert "skipped: scenario not available" in line and line.endswith("| n/a |")
    assert not suite._scenario_available("no_such_scenario")


def test_markdown_table_has_the_columns_and_targets(run):
    _, out, _ = run
    text = (out / "suite.md").read_text()
    # the default mode (the tests' VMAS_ROS_COMPILE=0 keeps it eager): a column says how each point ran
    assert ("| workload | envs | agents | default mode | vmas_ros ms/step | VMAS ms/step | ratio | first run s "
            "| target | met? |" in text)
    assert text.startswith("# Benchmark suite: vmas_ros vs VMAS 1.5.2\n\nModes measured: default. ")
    (line,) = [line for line in text.splitlines() if line.startswith("| memory_30k")]
    assert "<= 1x" in line and " MB" in line and "| eager |" in line
    assert "### scaling_envs" in text and "### scaling_agents\n" in text and "### scaling_agents_sparse\n" in text
    assert "side 0.1·√N" in text and "side 0.5·√N, about 3% covered" in text


def _row(workload, side, median_s, value=None, metric="time", **extra):
    row = {"run_id": "r", "workload": workload, "side": side, "num_envs": 1, "n_agents": 3, "metric": metric,
           "status": "ok", "note": "", "median_s": median_s, "times_s": [median_s] * 3,
           "value": value if value is not None or median_s is None else median_s * 10, "extrapolated": False, "steps": 100}
    row.update(extra)
    return row


@pytest.mark.parametrize("workload,ours,theirs,met", [
    ("spread_1", 1.0, 5.0, True),  # exactly the target counts as met
    ("spread_1", 1.0, 4.99, False),
    ("spheres_100", 0.1, 2.5, True),
    ("mpe_1k", 1.0, 299.0, False),
    ("spread_1k", 1.0, 3.0, None),  # no target
])
def test_speed_targets_are_evaluated_on_peer_over_ours(workload, ours, theirs, met):
    peer = "mpe" if workload == "mpe_1k" else "vmas"
    (entry,) = summarize([_row(workload, "vmas_ros", ours), _row(workload, peer, theirs)])
    assert entry["ratio"] == pytest.approx(theirs / ours)
    assert entry["met"] is met
    assert ("✓ met" if met else "✗ not met" if met is False else "| - | - |") in format_suite_table([entry])


@pytest.mark.parametrize("ours,theirs,met", [(900.0, 1000.0, True), (1000.0, 1000.0, True), (1001.0, 1000.0, False)])
def test_memory_target_is_ours_over_theirs_at_most_one(ours, theirs, met):
    rows = [_row("memory_30k", "vmas_ros", 1.0, ours, "memory"), _row("memory_30k", "vmas", 1.0, theirs, "memory")]
    (entry,) = summarize(rows)
    assert entry["ratio"] == pytest.approx(ours / theirs) and entry["met"] is met


def test_no_ratio_without_both_sides_and_targets_table():
    rows = [_row("transport_10k", "vmas_ros", 1.0), _row("transport_10k", "vmas", None, status="error", note="boom")]
    (entry,) = summarize(rows)
    assert entry["ratio"] is None and entry["met"] is None and entry["peer_status"] == "error: boom"
    assert evaluate_target(None, (">=", 3.0)) is None and evaluate_target(2.0, None) is None
    assert set(TARGETS) < set(suite.WORKLOADS)
    with pytest.raises(ValueError, match="'=='"):
        evaluate_target(1.0, ("==", 1.0))


def test_missing_peer_and_failing_workload_do_not_stop_the_suite(monkeypatch, capsys):
    monkeypatch.setattr(suite._mpe, "_peer_installed", lambda peer: False)
    rows = suite.run_suite(["spread_1"], steps=1, repeats=1, warmup=0, threads=1, progress=False)
    assert [(r["side"], r["status"]) for r in rows] == [("vmas_ros", "ok"), ("vmas", "skipped")]
    assert "not installed" in rows[1]["note"]

    def broken(*args, **kwargs):
        raise RuntimeError("kaput")

    monkeypatch.setattr(suite, "_env_cases", broken)
    rows = suite.run_suite(["spread_1", "spheres_100"], steps=1, repeats=1, warmup=0, progress=False, scale=0.01,
                           peers=[])
    assert [(r["workload"], r["status"]) for r in rows][:2] == [("spread_1", "error"), ("spread_1", "skipped")]
    assert "RuntimeError: kaput" in rows[0]["note"] and "kaput" in capsys.readouterr().err
    assert rows[2]["workload"] == "spheres_100" and rows[2]["status"] == "ok"


@pytest.mark.parametrize("argv,needle", [
    (["--workloads", "spread_1", "spred_30k"],
     "'spred_30k' (did you mean 'spread_30k'?); valid workloads: spread_1,"),
    (["--scale", "0"], "scale must be a finite number > 0 (e.g. 0.01), got 0.0"),
    (["--scale", "nan"], "got nan"),
    (["--steps", "0"], "steps must be a positive integer, got 0"),
    (["--repeats", "-1"], "repeats must be a positive integer, got -1"),
    (["--warmup", "-1"], "warmup must be a non-negative integer, got -1"),
    (["--threads", "0"], "threads must be a positive integer or None, got 0"),
    (["--max-peer-agents", "0"], "max_peer_agents must be a positive integer or None, got 0"),
    (["--curve-agents", "10", "0"], "curve_agents must be positive integers; bad value(s): [0]"),
    (["--curve-envs", "-5"], "curve_envs must be positive integers; bad value(s): [-5]"),
    (["--curve-agents-sparse", "100", "0"], "curve_agents_sparse must be positive integers; bad value(s): [0]"),
    (["--peers", "vmas", "gazebo"], "unknown peer(s) ['gazebo']; valid peers: ['vmas', 'mpe']"),
    (["--devices", "cuda"], "cpu only (its targets are CPU targets); got devices ['cuda']; valid: cpu"),
    (["--num-envs", "7"], "--num-envs 7 is for 'bench mpe'"),
    (["--modes", "eager", "compild"], "unknown mode(s) ['compild']; valid modes: default, eager, compiled"),
    (["--modes", "default", "eager"], "--modes default measures vmas_ros as make_env builds it without flags"),
    (["--compile-physics", "--modes", "eager", "compiled"],
     "--compile-physics means --modes compiled, but --modes eager compiled was given too"),
    (["--compile-physics", "--modes", "eager"], "but --modes eager was given too"),
    (["--modes", "compiled", "--warmup", "0"], "needs --warmup >= 1 (its first runs compile), got 0"),
    (["--compile-physics", "--warmup", "0"], "needs --warmup >= 1 (its first runs compile), got 0"),
])
def test_bad_options_exit_2_naming_the_value(argv, needle, capsys, tmp_path):
    args = parse_bench_args(["suite"] + argv + ["--out", str(tmp_path / "never"), "--no-progress"])
    assert bench_cli.run_bench_command(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("vmas-ros bench suite: ") and needle in err, err
    assert not (tmp_path / "never").exists()


def test_unknown_benchmark_lists_suite_and_run_suite_validates(capsys):
    args = parse_bench_args(["atari", "--no-progress"])
    assert bench_cli.run_bench_command(args) == 2
    assert "unknown benchmark 'atari'; valid: mpe, suite" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown workload 'nope'"):
        suite.run_suite(["nope"], progress=False)
    with pytest.raises(ValueError, match="workloads must be a non-empty list"):
        suite.run_suite("spread_1", progress=False)


# ------------------------------------------------------------------- modes
def _modes_rows():
    """spread_1 met by compiled only, spread_30k by both, transport_10k by neither, memory eager only, curves."""
    c = dict(compiled=True)
    return [
        _row("spread_1", "vmas_ros", 1.0), _row("spread_1", "vmas_ros_compiled", 0.5, **c),
        _row("spread_1", "vmas", 3.0),
        _row("spread_30k", "vmas_ros", 1.0), _row("spread_30k", "vmas_ros_compiled", 0.5, **c),
        _row("spread_30k", "vmas", 2.5),
        _row("transport_10k", "vmas_ros", 1.0), _row("transport_10k", "vmas_ros_compiled", 0.8, **c),
        _row("transport_10k", "vmas", 2.0),
        _row("memory_30k", "vmas_ros", 1.0, 900.0, "memory"), _row("memory_30k", "vmas", 1.0, 1000.0, "memory"),
        _row("scaling_envs", "vmas_ros", 0.2, env_steps_per_s=500.0),
        _row("scaling_envs", "vmas_ros_compiled", 0.1, env_steps_per_s=1000.0, **c),
        _row("scaling_envs", "vmas", 0.4, env_steps_per_s=250.0),
        _row("scaling_agents", "vmas_ros", 1.0),
        _row("scaling_agents", "vmas_ros_compiled", None, status="error", note="RuntimeError: no compiler", **c),
        _row("scaling_agents", "vmas", 4.0),
    ]


def test_compiled_side_gets_its_own_ratio_and_met_by():
    by = {e["workload"]: e for e in summarize(_modes_rows())}
    spread_1, spread_30k, transport, memory = by["spread_1"], by["spread_30k"], by["transport_10k"], by["memory_30k"]
    # peer is still VMAS, not the compiled side
    assert {e["peer"] for e in by.values()} == {"vmas"}
    assert spread_1["ratio"] == pytest.approx(3.0) and spread_1["compiled_ratio"] == pytest.approx(6.0)
    assert spread_1["vmas_ros"] == pytest.approx(10.0) and spread_1["compiled"] == pytest.approx(5.0)
    assert (spread_1["met"], spread_1["met_by"]) == (True, "compiled")  # 3x < 5x <= 6x
    assert (spread_30k["met"], spread_30k["met_by"]) == (True, "eager")  # 2.5x and 5x, both >= 2x: eager named
    assert transport["compiled_ratio"] == pytest.approx(2.5)
    assert (transport["met"], transport["met_by"]) == (False, None)  # 2x and 2.5x, both < 3x
    assert memory["compiled"] is None and memory["compiled_ratio"] is None and memory["compiled_status"] == "missing"
    assert (memory["met"], memory["met_by"], memory["vmas_ros_mode"]) == (True, "eager", "eager")
    envs = by["scaling_envs"]
    assert envs["compiled_env_steps_per_s"] == 1000.0 and envs["compiled_ratio"] == pytest.approx(4.0)
    agents = by["scaling_agents"]
    assert agents["compiled"] is None and agents["compiled_ratio"] is None
    assert agents["compiled_status"] == "error: RuntimeError: no compiler" and agents["ratio"] == pytest.approx(4.0)


def test_table_with_compiled_columns():
    text = format_suite_table(summarize(_modes_rows()))
    lines = text.splitlines()
    assert lines[0] == ("| workload | envs | agents | vmas_ros ms/step | VMAS ms/step | ratio | compiled ms/step | "
                        "compiled ratio | target | met? |")
    assert lines[1] == "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    assert lines[2] == ("| spread_1 | 1 | 3 | 10.000 | 30.000 | 3.00x | 5.000 | 6.00x | >= 5x | "
                        "✓ met (compiled only) |")
    assert lines[3] == "| spread_30k | 1 | 3 | 10.000 | 25.000 | 2.50x | 5.000 | 5.00x | >= 2x | ✓ met (eager) |"
    assert lines[4] == "| transport_10k | 1 | 3 | 10.000 | 20.000 | 2.00x | 8.000 | 2.50x | >= 3x | ✗ not met |"
    assert lines[5] == "| memory_30k | 1 | 3 | 900 MB | 1,000 MB | 0.90x | - | - | <= 1x | ✓ met (eager) |"
    assert ("| num_envs | vmas_ros ms/step | VMAS ms/step | vmas_ros env-steps/s | VMAS env-steps/s | speed-up | "
            "compiled ms/step | compiled env-steps/s | compiled speed-up |") in lines
    assert "| 1 | 2.000 | 4.000 | 500 | 250 | 2.00x | 1.000 | 1,000 | 4.00x |" in lines
    assert "| agents | vmas_ros ms/step | VMAS ms/step | speed-up | compiled ms/step | compiled speed-up |" in lines
    assert "| 3 | 10.000 | 40.000 | 4.00x | error: RuntimeError: no compiler | - |" in lines
    assert "memory_30k is measured eager only" in text and "(compiled only) when only the compiled one" in text


def test_table_without_compiled_rows_is_unchanged():
    rows = [r for r in _modes_rows() if r["side"] != "vmas_ros_compiled"]
    summary = summarize(rows)
    assert all(e["compiled"] is None and e["compiled_status"] == "missing" for e in summary)
    assert [e["met_by"] for e in summary[:4]] == [None, "eager", None, "eager"]
    text = format_suite_table(summary)
    assert text.splitlines()[:6] == [
        "| workload | envs | agents | vmas_ros ms/step | VMAS ms/step | ratio | target | met? |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
        "| spread_1 | 1 | 3 | 10.000 | 30.000 | 3.00x | >= 5x | ✗ not met |",
        "| spread_30k | 1 | 3 | 10.000 | 25.000 | 2.50x | >= 2x | ✓ met |",
        "| transport_10k | 1 | 3 | 10.000 | 20.000 | 2.00x | >= 3x | ✗ not met |",
        "| memory_30k | 1 | 3 | 900 MB | 1,000 MB | 0.90x | <= 1x | ✓ met |",
    ]
    assert "| agents | vmas_ros ms/step | VMAS ms/step | speed-up |" in text.splitlines()
    assert "compiled" not in text and "eager" not in text


def test_compiled_only_is_the_vmas_ros_side_flagged_compiled():
    rows = [_row("spread_1", "vmas_ros", 0.5, compiled=True), _row("spread_1", "vmas", 3.0)]
    (entry,) = summarize(rows)
    assert entry["vmas_ros"] == pytest.approx(5.0) and entry["ratio"] == pytest.approx(6.0)
    assert (entry["vmas_ros_mode"], entry["met"], entry["met_by"]) == ("compiled", True, "compiled")
    assert entry["compiled"] is None and entry["compiled_status"] == "missing"
    lines = format_suite_table([entry]).splitlines()
    assert lines[0] == "| workload | envs | agents | vmas_ros ms/step | VMAS ms/step | ratio | target | met? |"
    assert lines[2] == "| spread_1 | 1 | 3 | 5.000 | 30.000 | 6.00x | >= 5x | ✓ met |"
    assert lines[-1].startswith("vmas_ros ran compiled (--modes compiled")


def test_modes_plan_the_sides_and_compile_physics_is_an_alias():
    assert suite.resolve_modes(None) == ("default",)
    assert suite.resolve_modes(None, compile_physics=True) == ("compiled",)
    assert suite.resolve_modes(["compiled", "eager", "compiled"]) == ("eager", "compiled")
    assert suite.resolve_modes(["compiled"], compile_physics=True) == ("compiled",)
    with pytest.raises(ValueError, match=r"unknown mode\(s\) \['jit'\]; valid modes: default, eager, compiled"):
        suite.run_suite(["spread_1"], modes=["jit"], progress=False)
    with pytest.raises(ValueError, match="--compile-physics means --modes compiled"):
        suite.run_suite(["spread_1"], modes=["eager"], compile_physics=True, progress=False)
    with pytest.raises(ValueError, match="modes must be a non-empty list"):
        suite.resolve_modes("compiled")
    units = {u.workload.name: u for u in suite.plan_suite(["spread_1", "memory_30k", "mpe_1k"], peers=["vmas", "mpe"],
                                                          modes=("eager", "compiled"))}
    assert units["spread_1"].sides[:2] == ["vmas_ros", "vmas_ros_compiled"]
    assert units["spread_1"].compiled_sides == ("vmas_ros_compiled",)
    assert units["mpe_1k"].compiled_sides == ("vmas_ros_compiled",)
    assert units["memory_30k"].sides[0] == "vmas_ros" and units["memory_30k"].compiled_sides == ()
    (only,) = suite.plan_suite(["spread_1"], peers=[], modes=("compiled",))
    assert (only.sides, only.compiled_sides) == (["vmas_ros"], ("vmas_ros",))


@pytest.mark.parametrize("setting", ["auto", "0", "1"])
def test_the_default_mode_builds_what_make_env_builds(monkeypatch, setting):
    """One vmas_ros side per point, built as make_env builds it without flags; whether its timed runs
    were compiled is known only after its warm-up (timing.through_the_switch), so none is planned."""
    monkeypatch.setenv("VMAS_ROS_COMPILE", setting)
    units = suite.plan_suite(["spread_1", "spread_30k", "transport_10k", "spheres_100", "memory_30k", "mpe_1k",
                              "scaling_envs"], peers=["vmas", "mpe"], modes=("default",))
    assert all(u.default_mode and u.sides[0] == "vmas_ros" and "vmas_ros_compiled" not in u.sides
               and u.compiled_sides == () for u in units)


def test_the_default_modes_warm_up_steps_on_to_its_switch(monkeypatch, caplog):
    """The warm-up runs on to the default mode's switch when it comes within the cap (here the switch finds
    no compiler, so nothing compiles and the test stays quick), and says how the timed runs will go."""
    from torch._inductor import config

    from vmas_ros.bench import common, timing
    from vmas_ros.simulator import compile_default

    monkeypatch.setattr(compile_default, "_said", set())
    compile_default._cpu_compiler_missing.cache_clear()
    env = vmas_ros.make_env("simple_spread", num_envs=2, seed=0, compile_physics=False)
    actions = [[torch.zeros(2, 2) for _ in env.agents]] * 3
    said = []

    def run():
        for action in actions:
            env.step(action)

    env.world.compile_physics(after_steps=common.DEFAULT_MODE_WARMUP_MAX_STEPS + 1)
    timing.through_the_switch(env, run, actions, said.append)()
    assert env.world._compiled.steps_taken == 3 and said == [False]  # beyond the cap: timed eager
    env.world.compile_physics(after_steps=10)
    with config.patch({"cpp.cxx": ("/nonexistent/c++",)}), caplog.at_level(logging.WARNING, logger="vmas_ros"):
        timing.through_the_switch(env, run, actions, said.append)()
    compile_default._cpu_compiler_missing.cache_clear()
    # planned at step 3 + 10 = 13: the warm-up stepped on up to and through step 13, where the switch came
    assert env.world._compiled.steps_taken == 14 and said == [False, False]
    assert env.world.compiled_from_step is None and "no working C++ compiler" in caplog.text


def test_a_failing_compiled_side_does_not_lose_the_others(monkeypatch, capsys):
    real = suite._spheres_case

    def spheres(side, n_agents, num_envs, steps, seed, compiled=False, **layout):
        case = real(side, n_agents, num_envs, steps, seed, False, **layout)  # eager: no compiling in this test
        if not compiled:
            return case

        def run():
            raise RuntimeError("no C++ compiler")

        return suite.Case(run=run, setup=case.setup, device="cpu")

    monkeypatch.setattr(suite, "_spheres_case", spheres)
    rows = suite.run_suite(["scaling_agents"], curve_agents=[2], steps=1, repeats=2, warmup=1, threads=1,
                           peers=[], progress=False, modes=["eager", "compiled"])
    assert [(r["side"], r["status"], r["compiled"]) for r in rows] == [
        ("vmas_ros", "ok", False), ("vmas_ros_compiled", "error", True), ("vmas", "skipped", False)]
    assert rows[0]["repeats"] == 2 and len(rows[0]["times_s"]) == 2
    assert rows[1]["note"] == "RuntimeError: no C++ compiler" and "no C++ compiler" in capsys.readouterr().err


@pytest.mark.slow
def test_eager_and_compiled_side_by_side(tmp_path):
    """One real run in both modes (torch.compile compiles in the warm-up: seconds)."""
    argv = ["suite", "--workloads", "spread_1", "--modes", "eager", "compiled", "--steps", "2", "--repeats", "1",
            "--warmup", "1", "--threads", "1", "--no-progress", "--no-plot", "--out", str(tmp_path)]
    assert bench_cli.run_bench_command(parse_bench_args(argv)) == 0
    document = json.loads((tmp_path / "suite.json").read_text())
    assert document["modes"] == ["eager", "compiled"]
    expected = [("vmas_ros", False), ("vmas_ros_compiled", True)] + ([("vmas", False)] if HAS_VMAS else [])
    assert [(r["side"], r["compiled"]) for r in document["rows"]] == expected
    for row in document["rows"]:
        assert row["status"] == "ok" and row["num_envs"] == 1 and row["steps"] == 2 and row["median_s"] > 0
    (entry,) = document["summary"]
    compiled_row = document["rows"][1]
    assert entry["compiled"] == pytest.approx(compiled_row["value"]) and entry["compiled_status"] == "ok"
    if HAS_VMAS:
        assert entry["compiled_ratio"] == pytest.approx(document["rows"][2]["median_s"] / compiled_row["median_s"])
    text = (tmp_path / "suite.md").read_text()
    assert "Modes measured: eager, compiled." in text
    assert "| vmas_ros ms/step | VMAS ms/step | ratio | compiled ms/step | compiled ratio | target | met? |" in text
    with open(tmp_path / "suite.csv", newline="") as handle:
        assert [(line["side"], line["compiled"]) for line in csv.DictReader(handle)] == [
            (side, str(flag)) for side, flag in expected]


def _orange_pixels(path) -> int:
    """Pixels of matplotlib's tab:orange (255, 127, 14), the compiled line's colour."""
    with Image.open(path) as image:
        pixels = np.asarray(image.convert("RGB")).astype(int)
    return int((np.abs(pixels - [255, 127, 14]).sum(axis=-1) < 30).sum())


def test_curve_plot_and_header_show_the_compiled_side(tmp_path):
    pytest.importorskip("matplotlib")
    rows = []
    for n in (1, 10, 100):
        for side, seconds in (("vmas_ros", 0.2), ("vmas_ros_compiled", 0.1), ("vmas", 0.4)):
            rows.append(_row("scaling_envs", side, seconds * n, num_envs=n, n_agents=3, device="cpu", threads=1,
                             repeats=3, min_s=seconds * n * 0.9, max_s=seconds * n * 1.1, per_step_ms=seconds * n * 10,
                             env_steps_per_s=n * 100 / (seconds * n), compiled=side == "vmas_ros_compiled"))
    both = write_suite_results(rows, tmp_path / "both")
    eager = write_suite_results([r for r in rows if not r["compiled"]], tmp_path / "eager")
    assert _orange_pixels(both["envs_png"]) > 50 and _orange_pixels(eager["envs_png"]) == 0
    assert "Modes measured: eager, compiled." in both["md"].read_text()
    assert "Modes measured: eager. vmas_ros eager (no torch.compile)." in eager["md"].read_text()
    assert json.loads(both["json"].read_text())["modes"] == ["eager", "compiled"]
