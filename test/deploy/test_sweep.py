"""``deploy-eval --latency-sweep``: the latencies it takes, the table it builds, where success stops transferring.

The fleet runs themselves are deploy-eval's (test_deploy_eval.py runs one
end to end); here each latency's totals are given, as a run would return them.
"""
from __future__ import annotations

import json

import pytest

from vmas_ros.deploy import sweep


@pytest.mark.parametrize("text, expected", [("0,0.05,0.2", [0.0, 0.05, 0.2]), ("0.1", [0.1])])
def test_latencies_parse(text, expected):
    assert sweep.parse_latencies(text) == expected


@pytest.mark.parametrize("text, named", [("0,fifty", "'0,fifty'"), ("0,50", "50.0"), ("-0.1", "-0.1"),
                                         ("0.1,0.05", "increase"), ("0,0", "increase"), ("nan", "nan")])
def test_bad_latencies_are_refused_by_value(text, named):
    with pytest.raises(ValueError, match="--latency-sweep") as error:
        sweep.parse_latencies(text)
    assert named in str(error.value)


def totals(engine: float, fleet: float, fleet_collisions: float = 0.1) -> dict:
    return {"episodes": 100, "engine_success_rate": engine, "fleet_success_rate": fleet,
            "engine_time_to_goal": 6.0, "fleet_time_to_goal": 7.0, "engine_collisions_per_episode": 0.05,
            "fleet_collisions_per_episode": fleet_collisions, "coverage_ratio": 1.1}


def test_the_sweep_runs_every_latency_in_its_folder_and_names_where_success_falls(tmp_path):
    fleet = {0.0: 0.95, 0.05: 0.93, 0.1: 0.86, 0.2: 0.40}  # engine 0.96: 90% of it is 0.864
    seen = []

    def fleet_report(folder, latency):
        seen.append((folder.name, latency))
        assert folder.is_dir()
        return totals(0.96, fleet[latency], fleet_collisions=latency)

    text = sweep.run_sweep(tmp_path, list(fleet), fleet_report, policy="p.json", command="vmas-ros deploy-eval x",
                           per_robot_goals=True)
    assert seen == [("latency_000ms", 0.0), ("latency_050ms", 0.05), ("latency_100ms", 0.1),
                    ("latency_200ms", 0.2)]
    found = json.loads((tmp_path / "sweep.json").read_text())
    assert found["first_below"] == 0.1 and [r["latency"] for r in found["rows"]] == list(fleet)
    assert found["rows"][2]["success_ratio"] == pytest.approx(0.86 / 0.96)
    assert "| 100 | 100 | 96% | 86% | 0.90 |" in text  # 0.896 rounds up in the table, and is still below
    assert "falls below 90% of the engine's at 100 ms" in text and text == (tmp_path / "sweep.md").read_text()
    assert (tmp_path / "sweep.png").stat().st_size > 1000


def test_a_sweep_that_keeps_its_success_says_so_and_one_without_own_goals_is_refused(tmp_path):
    rows = sweep.sweep_rows([{"latency": v, "totals": totals(0.9, 0.9)} for v in (0.0, 0.1)])
    assert sweep.first_below(rows) is None
    assert "stays at or above 90% of the engine's up to 100 ms" in sweep.markdown(rows, "p", "c")
    with pytest.raises(ValueError, match="no goal per robot"):
        sweep.run_sweep(tmp_path, [0.0], lambda folder, latency: {}, policy="p", command="c", per_robot_goals=False)
