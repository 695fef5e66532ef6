"""``vmas-ros train-suite`` end to end at tiny sizes: run folders, report files, resume, refusals, heuristic line."""
import csv
import json

import pytest
import torch

import vmas_ros
from vmas_ros.cli import main
from vmas_ros.scenarios import make_heuristic
from vmas_ros.train.checkpoint import load_checkpoint
from vmas_ros.train.suite import DONE_MARKER

SCENARIOS = ["give_way", "balance"]
ALGORITHMS = ["mappo", "hetippo"]
ITERATIONS = 2
NUM_ENVS, MAX_STEPS = 20, 20
SIZES = ["--frames-per-batch", "400", "--num-envs", str(NUM_ENVS), "--max-steps", str(MAX_STEPS),
         "--minibatch-size", "200", "--epochs", "1", "--num-cells", "32", "--checkpoint-every", "1",
         "--threads", "1", "--quiet"]


def _suite(out, *extra, scenarios=SCENARIOS, algorithms=ALGORITHMS, iterations=ITERATIONS):
    return main(["train-suite", "--scenarios", *scenarios, "--algorithms", *algorithms, "--iterations",
                 str(iterations), *SIZES, "--out", str(out), *extra])


def _read(path):
    with open(path) as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    out = tmp_path_factory.mktemp("suite")
    assert _suite(out) == 0
    return out


@pytest.mark.slow
def test_every_run_has_its_folder_and_the_report_is_complete(suite):
    for scenario in SCENARIOS:
        for algorithm in ALGORITHMS:
            folder = suite / "runs" / f"{scenario}_{algorithm}_seed0"
            for name in ("config.json", "log.csv", "checkpoint.pt", DONE_MARKER, "policy.onnx"):
                assert (folder / name).is_file(), folder / name
            config = json.loads((folder / "config.json").read_text())
            assert (config["scenario"], config["algorithm"], config["seed"]) == (scenario, algorithm, 0)
            assert config["num_envs"] == NUM_ENVS and config["eval_episodes"] == 0
    rows = _read(suite / "curves.csv")
    assert len(rows) == len(SCENARIOS) * len(ALGORITHMS) * ITERATIONS
    assert {(r["scenario"], r["algorithm"]) for r in rows} == {(s, a) for s in SCENARIOS for a in ALGORITHMS}
    assert sorted({int(r["iteration"]) for r in rows}) == list(range(1, ITERATIONS + 1))
    assert all(r["episode_reward_mean"] not in ("", "nan") for r in rows)  # max_steps == steps per iteration
    for name in [f"{s}.png" for s in SCENARIOS] + ["figure3.png"]:
        data = (suite / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000, name
    summary = (suite / "summary.md").read_text()
    for text in ["MAPPO", "HetIPPO", "heuristic", *[f"`{s}`" for s in SCENARIOS]]:
        assert text in summary


@pytest.mark.slow
def test_heuristic_line_is_in_the_data_in_training_units(suite):
    """heuristics.csv holds the per-agent mean episode return, recomputed here independently."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vmas_ros.train.suite import SuiteRun
    from vmas_ros.train.suite_report import draw_scenario

    heuristics = {row["scenario"]: row for row in _read(suite / "heuristics.csv")}
    assert sorted(heuristics) == sorted(SCENARIOS)
    for scenario in SCENARIOS:
        row = heuristics[scenario]
        assert (int(row["num_envs"]), int(row["max_steps"])) == (NUM_ENVS, MAX_STEPS)
        env = vmas_ros.make_env(scenario, num_envs=NUM_ENVS, seed=0, continuous_actions=True)
        policy = make_heuristic(scenario)
        obs, total = env.reset(), torch.zeros(NUM_ENVS)
        alive = torch.ones(NUM_ENVS, dtype=torch.bool)
        for _ in range(MAX_STEPS):
            obs, rews, dones, _ = env.step([policy.compute_action(o, u_range=a.u_range)
                                            for o, a in zip(obs, env.agents)])
            total += torch.stack(rews).mean(dim=0) * alive  # mean over agents, like the trainer's log
            alive &= ~dones
        assert float(row["mean_return"]) == pytest.approx(float(total.mean()), rel=1e-4, abs=1e-5)
    # and the plot draws it as a line labelled "heuristic" at that height
    runs = [SuiteRun(s, a, 0, None) for s in SCENARIOS for a in ALGORITHMS]
    histories = {r.name: load_checkpoint(suite / "runs" / r.name)["history"] for r in runs}
    fig, axes = plt.subplots()
    draw_scenario(axes, runs, histories, "balance", ALGORITHMS, float(heuristics["balance"]["mean_return"]))
    lines = {line.get_label(): line for line in axes.get_lines()}
    assert set(lines) == {"MAPPO", "HetIPPO", "heuristic"}
    assert list(lines["heuristic"].get_ydata()) == [float(heuristics["balance"]["mean_return"])] * 2
    plt.close(fig)


@pytest.mark.slow
def test_rerun_skips_finished_runs_and_resumes_partial_ones(suite, tmp_path, capsys):
    folder = suite / "runs" / "balance_mappo_seed0"
    stamps = {p: p.stat().st_mtime_ns for p in (suite / "runs").glob("*/checkpoint.pt")}
    capsys.readouterr()
    assert _suite(suite) == 0
    assert "4 runs (0 trained, 0 resumed, 4 skipped)" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    # a partial run (no done marker, checkpoint at 2 of 3 iterations) continues from its checkpoint
    before = load_checkpoint(folder)["history"]
    (folder / DONE_MARKER).unlink()
    assert _suite(suite, "--report-dir", str(tmp_path / "report"), scenarios=["balance"], algorithms=["mappo"],
                  iterations=3) == 0
    assert "1 runs (0 trained, 1 resumed, 0 skipped)" in capsys.readouterr().out
    after = load_checkpoint(folder)["history"]
    assert len(after) == 3 and after[:2] == before
    assert len(_read(tmp_path / "report" / "curves.csv")) == 3
    # a folder trained with other settings is refused, not mixed into the curve
    assert _suite(suite, "--lr", "0.01", scenarios=["balance"], algorithms=["mappo"]) == 2
    assert "lr=0.0005" in capsys.readouterr().err


@pytest.mark.parametrize("args, expected", [
    (["--algorithms", "mappo", "sac"], "'sac'"),
    (["--scenarios", "transport", "no_such_scenario"], "'no_such_scenario'"),
    (["--scenarios", "wheel", "wheel"], "wheel given more than once"),
    (["--seeds", "-3"], "-3"),
    (["--iterations", "0"], "iterations must be a positive int, got 0"),
    (["--frames-per-batch", "1000", "--num-envs", "60"], "frames_per_batch (1000)"),
    (["--threads", "0"], "--threads must be >= 1, got 0"),
    (["--gamma", "1.5"], "gamma must be in [0.0, 1.0], got 1.5"),
])
def test_bad_values_are_refused_with_exit_2_naming_the_value(args, expected, tmp_path, capsys):
    try:
        code = main(["train-suite", "--out", str(tmp_path / "out"), "--quiet", *args])
    except SystemExit as exit_:  # argparse's own refusals (choices, types)
        code = exit_.code
    assert code == 2
    assert expected in capsys.readouterr().err
    assert not (tmp_path / "out" / "runs").exists()


def test_config_file_may_not_set_per_run_fields(tmp_path, capsys):
    config = tmp_path / "suite.yaml"
    config.write_text("lr: 0.001\nalgorithm: ippo\n")
    assert main(["train-suite", "--config", str(config), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    assert "['algorithm']" in capsys.readouterr().err
