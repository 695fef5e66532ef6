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


def test_a_cold_cache_is_empty_fresh_and_gone_after(tmp_path, monkeypatch):
    """``--process-cold-cache``: every vmas_ros child compiles into an empty cache folder of its own, removed
    after it exits; VMAS's children are left as they are."""
    seen = tmp_path / "seen.txt"
    monkeypatch.delenv("TORCHINDUCTOR_CACHE_DIR", raising=False)
    monkeypatch.setattr(process, "_SCRIPT", "import os, sys, json\n"
                        f"cache = os.environ.get('TORCHINDUCTOR_CACHE_DIR', '-')\n"
                        f"empty = cache == '-' or not os.listdir(cache)\n"
                        f"open({str(seen)!r}, 'a').write(json.loads(sys.argv[1])['module'] + ' ' + cache + ' '"
                        f" + str(empty) + '\\n')\n")
    for side in ("vmas_ros", "vmas_ros", "vmas"):
        process.run_once(side, "simple_spread", 1, 1, mode="eager", cold_cache=True)
    process.run_once("vmas_ros", "simple_spread", 1, 1, mode="eager")
    lines = [line.split() for line in seen.read_text().splitlines()]
    assert [line[0] for line in lines] == ["vmas_ros", "vmas_ros", "vmas", "vmas_ros"]
    first, second = lines[0][1], lines[1][1]
    assert first != second and all(line[2] == "True" for line in lines[:2])
    assert not any(__import__("os").path.exists(path) for path in (first, second))
    assert lines[2][1] == lines[3][1] == "-"
