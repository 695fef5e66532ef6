"""``vmas-ros bench process``: whole processes of vmas_ros and VMAS, timed from start to exit, with peak RSS."""
from __future__ import annotations

import json

import pytest

from vmas_ros.bench import process
from vmas_ros.bench.cli import parse_bench_args, run_bench_command


@pytest.mark.parametrize("name, expected", [("transport_32", ("transport", 32)),
                                            ("simple_spread_1", ("simple_spread", 1))])
def test_workload_names_are_scenario_and_env_count(name, expected):
    assert process.parse_workload(name) == expected


@pytest.mark.parametrize("name, fragment", [("transport", "must be <scenario>_<num_envs>"),
                                            ("transport_0", "must be <scenario>_<num_envs>"),
                                            ("teleport_32", "unknown scenario 'teleport'")])
def test_bad_workloads_are_refused_by_name(name, fragment):
    with pytest.raises(ValueError, match=fragment):
        process.parse_workload(name)


def test_one_short_process_per_side_with_its_peak_memory(tmp_path):
    """The smallest real run: both sides as fresh interpreters; the child's peak RSS includes torch's import."""
    args = parse_bench_args(["process", "--process-workloads", "simple_spread_2", "--process-steps", "5",
                             "--repeats", "1", "--process-mode", "eager", "--out", str(tmp_path), "--no-progress"])
    assert run_bench_command(args) == 0
    (row,) = json.loads((tmp_path / "process.json").read_text())
    assert row["workload"] == "simple_spread_2" and row["steps"] == 5 and row["mode"] == "eager"
    for side in ("vmas_ros", "vmas"):
        assert len(row[f"{side}_samples_s"]) == 1 and 0.2 < row[f"{side}_s"] < 120
        assert 100 < row[f"{side}_peak_mb"] < 4000  # torch alone takes about 200 MB
    assert row["time_ratio"] == pytest.approx(row["vmas_ros_s"] / row["vmas_s"])
    assert "| simple_spread_2 | 5 |" in (tmp_path / "process.md").read_text()


def test_a_bad_mode_or_a_failing_child_is_reported():
    with pytest.raises(ValueError, match="--process-mode must be one of default, eager, compiled"):
        process.run_process_benchmark(["transport_2"], [5], 1, mode="fast", progress=False)
    with pytest.raises(RuntimeError, match="exited 1"):
        process.run_once("no_such_library", "transport", 2, 5)
