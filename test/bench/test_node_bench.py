"""``vmas-ros bench node``: a real run (sim_node in-process, a subscriber process) at a tiny
duration, through the command line. Benchmarks are measurements: nothing here asserts on speed,
only that the run happened as documented and its files say so."""
from __future__ import annotations

import csv
import json

import pytest

from vmas_ros.bench.cli import parse_bench_args
from vmas_ros.bench import cli as bench_cli
from vmas_ros.bench.node import NODE_COLUMNS

pytestmark = [pytest.mark.ros, pytest.mark.serial]  # it measures a node's steps per second


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("node_bench")
    argv = ["node", "--duration", "0.5", "--repeats", "2", "--warmup", "0", "--no-progress", "--out", str(out),
            "--scenario-kwargs", '{"n_agents": 2}', "--lidar-rays", "8", "--unpaced-batch-ms", "3"]
    code = bench_cli.run_bench_command(parse_bench_args(argv))
    return code, out, json.loads((out / "node_benchmark.json").read_text())


def test_writes_csv_json_and_table(run):
    code, out, document = run
    assert code == 0
    with open(out / "node_benchmark.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == NODE_COLUMNS and len(rows) == 2
    assert all(int(r["steps"]) > 0 and float(r["steps_per_s"]) > 0 for r in rows)
    assert all(float(r["unpaced_batch_ms"]) == 3.0 for r in rows)  # the node ran with the option's value
    assert "steps/s" in (out / "node_benchmark.md").read_text()
    assert document["machine"]["torch"] and len(document["rows"]) == 2


def test_the_subscriber_process_received_the_core_topics(run):
    _, _, document = run
    summary = document["summary"]
    expected = {"/clock"} | {f"/agent_{i}/{leaf}" for i in range(2) for leaf in ("pose", "odom", "scan")}
    assert set(summary["topics"]) == expected
    received = summary["received_by_topic"]
    assert set(received) == expected and all(received[t] > 0 for t in expected)
    assert 0 < summary["messages_received"] <= summary["messages_published"]


def test_the_breakdown_covers_the_step(run):
    _, _, document = run
    for row in document["rows"]:
        parts = sum(row[f"{name}_us"] for name in ("actions", "engine", "lidar", "convert", "publish"))
        assert row["engine_us"] > 0 and row["lidar_us"] > 0 and row["publish_us"] > 0
        # the parts come from the profiled window that follows each plain one (timers in the step)
        assert row["profiled_steps_per_s"] > 0
        assert parts + row["executor_us"] == pytest.approx(1e6 / row["profiled_steps_per_s"], rel=1e-3)


def test_bad_options_exit_2(tmp_path, capsys):
    code = bench_cli.run_bench_command(parse_bench_args(["node", "--duration", "0", "--out", str(tmp_path)]))
    assert code == 2 and "duration" in capsys.readouterr().err
    code = bench_cli.run_bench_command(parse_bench_args(["node", "--unpaced-batch-ms", "-1", "--out", str(tmp_path)]))
    assert code == 2 and "unpaced_batch_ms must be in [0, 1000]" in capsys.readouterr().err
