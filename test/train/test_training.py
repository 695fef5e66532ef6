"""A short real training run through the CLI: it learns, writes every output, resumes and exports."""
import csv
import json
import math

import numpy as np
import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from vmas_ros.cli import main
from vmas_ros.policy import OnnxPolicy
from vmas_ros.train.algorithms import build_agent
from vmas_ros.train.checkpoint import load_checkpoint
from vmas_ros.train.config import TrainConfig

ITERATIONS = 20
FLAGS = ["--scenario", "simple", "--algorithm", "ippo", "--frames-per-batch", "4000", "--num-envs", "160",
         "--max-steps", "25", "--minibatch-size", "500", "--epochs", "4", "--lr", "0.003", "--gamma", "0.9",
         "--num-cells", "64", "--checkpoint-every", "10", "--eval-episodes", "4", "--quiet"]


def _rows(out):
    with open(out / "log.csv") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    assert main(["train", *FLAGS, "--iterations", str(ITERATIONS), "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_training_improves_and_writes_outputs(run):
    for name in ("config.json", "log.csv", "learning_curve.png", "checkpoint.pt", "eval.gif", "eval.json",
                 "policy.onnx", "policy.json"):
        assert (run / name).is_file() and (run / name).stat().st_size > 0, name
    rows = _rows(run)
    assert [int(r["iteration"]) for r in rows] == list(range(1, ITERATIONS + 1))
    assert int(rows[-1]["frames"]) == ITERATIONS * 4000
    rewards = [float(r["episode_reward_mean"]) for r in rows]
    assert all(math.isfinite(r) for r in rewards)
    first, last = np.mean(rewards[:3]), np.mean(rewards[-3:])
    assert last > first + 3.0, f"no learning: first iterations {rewards[:3]}, last {rewards[-3:]}"
    assert json.loads((run / "config.json").read_text())["algorithm"] == "ippo"
    assert json.loads((run / "eval.json").read_text())["episodes"] == 4
    assert load_checkpoint(run)["iteration"] == ITERATIONS


@pytest.mark.slow
def test_exported_policy_matches_trained_checkpoint(run, tmp_path):
    state = load_checkpoint(run / "checkpoint.pt")
    config = TrainConfig.from_dict(state["config"])
    info = state["env_info"]
    agent = build_agent(config, len(info["agents"]), info["observation_size"], info["action_size"],
                        torch.tensor(info["action_low"]), torch.tensor(info["action_high"]))
    agent.actor_network.load_state_dict(state["actor"])
    assert main(["export", "--checkpoint", str(run), "--out", str(tmp_path / "exported")]) == 0
    policy = OnnxPolicy.load(tmp_path / "exported.json")
    assert policy.agents == ["agent_0"] and policy.scenario == "simple" and policy.algorithm == "ippo"
    obs = torch.randn(32, 1, info["observation_size"])
    from tensordict import TensorDict
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        expected = agent.policy(TensorDict({("agents", "observation"): obs}, batch_size=[32]))[("agents", "action")]
    np.testing.assert_allclose(policy.act(obs.numpy()), expected.numpy(), atol=1e-5)
    # the export written at the end of training is the same policy
    np.testing.assert_allclose(OnnxPolicy.load(run / "policy.onnx").act(obs.numpy()), expected.numpy(), atol=1e-5)


@pytest.mark.slow
def test_resume_continues_from_checkpoint(run, tmp_path):
    import shutil

    resumed = tmp_path / "resumed"
    shutil.copytree(run, resumed)
    before = load_checkpoint(resumed)
    assert main(["train", "--resume", str(resumed), "--iterations", str(ITERATIONS + 2), "--eval-episodes", "0",
                 "--quiet"]) == 0
    after = load_checkpoint(resumed)
    assert after["iteration"] == ITERATIONS + 2 and after["frames"] == (ITERATIONS + 2) * 4000
    assert after["history"][:ITERATIONS] == before["history"]
    rows = _rows(resumed)
    assert len(rows) == ITERATIONS + 2
    # training continued from the saved weights, not from scratch: the reward stays at the trained level
    assert float(rows[-1]["episode_reward_mean"]) > np.mean([float(r["episode_reward_mean"]) for r in rows[:3]])
    assert any(not torch.equal(before["actor"][k], after["actor"][k]) for k in before["actor"])
    # a checkpoint of another scenario is refused
    assert main(["train", "--resume", str(resumed), "--scenario", "balance", "--iterations", "30", "--quiet"]) == 2


def test_export_refuses_missing_checkpoint(tmp_path, capsys):
    assert main(["export", "--checkpoint", str(tmp_path / "none.pt"), "--out", str(tmp_path / "x")]) == 2
    assert "does not exist" in capsys.readouterr().err
