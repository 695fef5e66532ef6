"""The MPE comparison benchmark: shape of its results and files, and argument errors.

Benchmarks are measurements, not timed tests: nothing here asserts on speed.
"""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import torch
from PIL import Image

from vmas_ros.bench.cli import parse_bench_args, run_bench_command
from vmas_ros.bench import mpe as bench
from vmas_ros.bench.timing import Case, time_alternating, time_callable

CAP = 2
NUM_ENVS = [1, 4]


@pytest.fixture(scope="module")
def rows():
    return bench.run_mpe_benchmark(NUM_ENVS, steps=3, repeats=1, mpe_max_envs=CAP, threads=1, progress=False)


def _sides():
    return ("vmas_ros",) + bench.available_peers()


def test_every_side_and_num_envs_has_a_row_with_positive_finite_times(rows):
    keys = [(r["side"], r["device"], r["num_envs"]) for r in rows]
    assert len(keys) == len(set(keys)), "one row per side, device and num_envs"
    for side in _sides():
        devices = bench.default_devices() if side != "mpe" else ("cpu",)
        for device in devices:
            for n in NUM_ENVS:
                assert (side, device, n) in keys, f"missing row {side}/{device}/{n}"
    for row in rows:
        assert row["steps"] == 3 and row["repeats"] == 1 and len(row["times_s"]) == 1
        for key in ("median_s", "min_s", "max_s", "per_step_ms", "env_steps_per_s"):
            assert math.isfinite(row[key]) and row[key] > 0, (key, row)
        assert row["min_s"] <= row["median_s"] <= row["max_s"]
        assert row["per_step_ms"] == pytest.approx(row["median_s"] / 3 * 1e3)
        assert row["env_steps_per_s"] == pytest.approx(row["num_envs"] * 3 / row["median_s"])
        assert row["threads"] == 1, "the pinned thread count is recorded"
    assert len({r["run_id"] for r in rows}) == 1


def test_extrapolated_exactly_for_mpe_rows_above_the_cap(rows):
    for row in rows:
        above = row["side"] == "mpe" and row["num_envs"] > CAP
        assert row["extrapolated"] is above, row
        assert row["measured_envs"] == (CAP if above else row["num_envs"])
    if "mpe" in bench.available_peers():
        (capped,) = [r for r in rows if r["side"] == "mpe" and r["extrapolated"]]
        # linear: the time of the CAP envs really stepped, times num_envs / CAP
        assert capped["median_s"] * CAP / capped["num_envs"] > 0


def test_ratios_come_from_the_rows_of_the_same_run(rows):
    ratios = bench.compute_ratios(rows)
    peers = bench.available_peers()
    assert len(ratios) == len(NUM_ENVS) * len(bench.default_devices()) * ("vmas" in peers) + len(NUM_ENVS) * len(
        bench.default_devices()) * ("mpe" in peers)
    by_key = {(r["side"], r["device"], r["num_envs"]): r for r in rows}
    for ratio in ratios:
        ours = by_key[("vmas_ros", ratio["device"], ratio["num_envs"])]
        theirs = by_key[(ratio["peer"], ratio["peer_device"], ratio["num_envs"])]
        assert ratio["run_id"] == ours["run_id"] == theirs["run_id"]
        assert ratio["speedup"] == pytest.approx(theirs["median_s"] / ours["median_s"])
        assert ratio["peer_extrapolated"] is theirs["extrapolated"]
    # rows of another run are never paired with these
    other = [dict(r, run_id="another run") for r in rows if r["side"] != "vmas_ros"]
    assert bench.compute_ratios([r for r in rows if r["side"] == "vmas_ros"] + other) == []


def test_table_lists_every_num_envs_and_marks_extrapolation(rows):
    table = bench.format_table(rows)
    lines = [line for line in table.splitlines() if line.startswith("| ")]
    assert lines[0].startswith("| num_envs |")
    assert [line.split("|")[1].strip() for line in lines[1:]] == [str(n) for n in NUM_ENVS]
    if "mpe" in bench.available_peers():
        assert "speed-up vs MPE" in lines[0] and "extrapolated" in table
        assert "\\*" in lines[-1] and "\\*" not in lines[1]


def test_result_files_are_written_and_readable(rows, tmp_path):
    pytest.importorskip("matplotlib")
    paths = bench.write_results(rows, tmp_path / "out")
    assert {"csv", "json", "png"} <= set(paths)
    with open(paths["csv"], newline="") as handle:
        table = list(csv.DictReader(handle))
    assert len(table) == len(rows)
    for line, row in zip(table, rows):
        assert line["side"] == row["side"] and int(line["num_envs"]) == row["num_envs"]
        assert float(line["median_s"]) == pytest.approx(row["median_s"])
        assert line["extrapolated"] == str(row["extrapolated"])
    document = json.loads(paths["json"].read_text())
    assert document["rows"] == json.loads(json.dumps(rows))
    assert document["ratios"] == json.loads(json.dumps(bench.compute_ratios(rows)))
    machine = document["machine"]
    assert machine["torch"] == torch.__version__ and machine["threads"] == [1]
    assert machine["cpu_count"] >= 1 and machine["date"] == rows[0]["run_id"]
    with Image.open(paths["png"]) as image:
        image.load()
        pixels = np.asarray(image.convert("RGB"))
    assert pixels.shape[0] > 100 and pixels.shape[1] > 100
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 10, "the plot is not blank"


def test_threads_are_restored_and_a_missing_peer_is_skipped_with_a_note(monkeypatch, capsys):
    before = torch.get_num_threads()
    monkeypatch.setattr(bench, "_peer_installed", lambda peer: peer != "vmas")
    rows = bench.run_mpe_benchmark([1], steps=1, repeats=1, peers=["vmas"], threads=1, progress=False,
                                   devices=["cpu"])
    assert torch.get_num_threads() == before
    assert {r["side"] for r in rows} == {"vmas_ros"}
    assert "'vmas' is not installed" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["mpe", "--num-envs", "1", "0"], "num_envs"),
        (["mpe", "--num-envs", "-3"], "num_envs"),
        (["mpe", "--peers", "vmas", "gazebo"], "unknown peer"),
        (["mpe", "--steps", "0"], "steps"),
        (["mpe", "--repeats", "0"], "repeats"),
        (["mpe", "--mpe-max-envs", "0"], "mpe_max_envs"),
        (["mpe", "--threads", "0"], "threads"),
        (["mpe", "--devices", "tpu"], "device"),
        (["atari"], "unknown benchmark"),
    ],
)
def test_bad_arguments_return_2_with_a_reason(argv, needle, capsys, tmp_path):
    args = parse_bench_args(argv + ["--out", str(tmp_path / "never"), "--no-progress"])
    assert run_bench_command(args) == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "never").exists()


def test_command_runs_prints_the_table_and_writes_files(capsys, tmp_path):
    pytest.importorskip("matplotlib")
    args = parse_bench_args(["mpe", "--num-envs", "1", "2", "--steps", "2", "--repeats", "1", "--mpe-max-envs", "1",
                   "--threads", "1", "--devices", "cpu", "--out", str(tmp_path), "--no-progress"])
    assert args.bench_num_envs == [1, 2] and args.mpe_max_envs == 1 and args.threads == 1
    assert run_bench_command(args) == 0
    out = capsys.readouterr().out
    assert "| num_envs |" in out and "mpe_benchmark.csv" in out
    for name in ("mpe_benchmark.csv", "mpe_benchmark.json", "mpe_benchmark.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_timer_calls_setup_before_every_run_and_alternates():
    calls = []
    timing = time_callable(lambda: calls.append("run"), repeats=3, warmup=2, setup=lambda: calls.append("setup"))
    assert calls == ["setup", "run"] * 5
    assert len(timing.times_s) == 3 and timing.min_s <= timing.median_s <= timing.max_s
    assert timing.threads == torch.get_num_threads()
    order = []
    cases = {name: Case(run=lambda name=name: order.append(name)) for name in "ABC"}
    time_alternating(cases, repeats=2, warmup=0)
    assert order == list("ABCABC")
    with pytest.raises(ValueError):
        time_callable(lambda: None, repeats=0)
