"""``vmas-ros train`` with collectors on a real local Ray cluster: placement, weight sync, a lost node, resume."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
import time

import pytest
import torch

from test.train.ray_cluster import TINY, LocalCluster, run_cli

pytestmark = [pytest.mark.slow, pytest.mark.serial]  # a local Ray cluster fills the machine


@pytest.fixture(scope="module")
def cluster():
    local = LocalCluster(workers=2)
    try:
        yield local
    finally:
        local.stop()


def _rows(path):
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_two_collectors_train_on_both_worker_nodes(cluster, tmp_path):
    out = tmp_path / "run"
    result = run_cli(["train", *TINY, "--iterations", "2", "--ray-address", cluster.address, "--collectors", "2",
                      "--out", str(out), "--quiet"])
    assert result.returncode == 0, result.stderr[-3000:]
    placed = json.loads((out / "collectors.json").read_text())
    assert placed["ray_address"] == cluster.address and placed["iteration"] == 2
    assert sorted(c["node_id"] for c in placed["collectors"]) == sorted(cluster.worker_ids())
    for collector in placed["collectors"]:
        # 4 envs x 10 steps per iteration each: the frames per batch are split, not multiplied
        assert collector["num_envs"] == 4 and collector["frames"] == 80
        assert collector["node_ip"] == "127.0.0.1" and collector["frames_per_second"] > 0
    rows = _rows(out / "log.csv")
    assert [int(r["frames"]) for r in rows] == [80, 160]
    assert all(float(r["frames_per_second"]) > 0 for r in rows)
    assert json.loads((out / "config.json").read_text())["collectors"] == 2
    assert (out / "policy.onnx").is_file()


def test_collectors_act_with_the_learners_current_weights(cluster):
    """Each batch's log-probs are those of the learner's policy at that moment, before and after an update."""
    import ray

    from vmas_ros.train.algorithms import build_agent
    from vmas_ros.train.config import TrainConfig
    from vmas_ros.train.ray_collection import RayCollection
    from vmas_ros.train.trainer import _make_env
    from vmas_ros.train.export import describe_env

    config = TrainConfig(scenario="balance", num_envs=8, frames_per_batch=40, minibatch_size=40, num_cells=16)
    info = describe_env(_make_env(config, 1, 0))
    agent = build_agent(config, len(info["agents"]), info["observation_size"], info["action_size"],
                        torch.tensor(info["action_low"]), torch.tensor(info["action_high"]))
    env_kwargs = dict(scenario="balance", num_envs=8, continuous_actions=True, max_steps=100, seed=5,
                      terminated_truncated=True)
    ray.init(address=cluster.address, log_to_driver=False)
    try:
        collection = RayCollection(env_kwargs, agent.policy, 5, 2, 1, "cpu", torch.device("cpu"), cluster.address)
        try:
            for _ in range(2):
                batch, _episodes = collection.collect()
                assert batch.batch_size == torch.Size([8, 5])
                with torch.no_grad():
                    dist = agent.policy.get_dist(batch)
                    expected = dist.log_prob(batch.get(("agents", "action")))
                torch.testing.assert_close(batch.get(("agents", "action_log_prob")), expected, atol=1e-4, rtol=1e-4)
                with torch.no_grad():
                    for parameter in agent.policy.parameters():
                        parameter.add_(0.05 * torch.randn_like(parameter))
                collection.policy_updated()
        finally:
            collection.close()
        # collector 0 steps envs seeded like a single-process run with the same seed and 4 envs
        from vmas_ros.envs.torchrl_env import TorchRLEnv

        reset = TorchRLEnv(_make_env(config.replace(num_envs=4), 4, 5)).reset()
        fresh = RayCollection(env_kwargs, agent.policy, 5, 2, 1, "cpu", torch.device("cpu"), cluster.address)
        try:
            batch, _ = fresh.collect()
        finally:
            fresh.close()
        torch.testing.assert_close(batch[:4, 0].get(("agents", "observation")), reset.get(("agents", "observation")))
        with pytest.raises(ValueError, match=r"3 collectors x 1 CPU need 3 CPUs; the Ray cluster has \d free of 2"):
            RayCollection({**env_kwargs, "num_envs": 6}, agent.policy, 5, 3, 1, "cpu", torch.device("cpu"),
                          cluster.address)
    finally:
        ray.shutdown()


def test_train_suite_runs_are_tasks_on_both_worker_nodes(cluster, tmp_path):
    out = tmp_path / "suite"
    suite = ["train-suite", "--scenarios", "balance", "wheel", "--algorithms", "mappo", "--iterations", "1",
             "--max-steps", "10", "--ray-address", cluster.address, "--out", str(out), "--quiet",
             "--num-envs", "8", "--frames-per-batch", "80", "--minibatch-size", "40", "--epochs", "1",
             "--num-cells", "16"]
    result = run_cli(suite)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "2 runs (2 trained, 0 resumed, 0 skipped)" in result.stdout
    nodes = []
    for name in ("balance_mappo_seed0", "wheel_mappo_seed0"):
        run = out / "runs" / name
        assert {"checkpoint.pt", "log.csv", "policy.onnx", "config.json"} <= {p.name for p in run.iterdir()}
        nodes.append(json.loads((run / "suite_done.json").read_text())["node_id"])
        assert json.loads((run / "config.json").read_text())["out"] == str(run)
    # two one-CPU tasks at once on two one-CPU workers: one on each
    assert sorted(nodes) == sorted(cluster.worker_ids())
    assert (out / "summary.md").is_file()
    again = run_cli(suite)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "2 runs (0 trained, 0 resumed, 2 skipped)" in again.stdout


def test_a_lost_node_stops_the_run_and_resume_continues(cluster, tmp_path):
    doomed = cluster.add_worker()
    out = tmp_path / "run"
    # three one-CPU collectors on three one-CPU workers: one per node, so one lands on the doomed node
    command = [sys.executable, "-m", "vmas_ros.cli", "train", *TINY, "--num-envs", "6", "--frames-per-batch", "60",
               "--iterations", "500", "--checkpoint-every", "1", "--ray-address", cluster.address,
               "--collectors", "3", "--out", str(out), "--quiet"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not ((out / "log.csv").is_file() and len(_rows(out / "log.csv")) >= 2):
            assert process.poll() is None, process.communicate()[1][-3000:]
            assert time.monotonic() < deadline, "training did not start"
            time.sleep(0.2)
        doomed_id = doomed.node_id
        cluster.remove(doomed)
        _stdout, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 1, stderr[-3000:]
    assert f"node {doomed_id}" in stderr and "--resume" in stderr, stderr[-3000:]
    done = len(_rows(out / "log.csv"))
    assert 2 <= done < 500
    result = run_cli(["train", "--resume", str(out), "--iterations", str(done + 1), "--collectors", "2", "--quiet"])
    assert result.returncode == 0, result.stderr[-3000:]
    assert f"resuming {out} at iteration {done}" in result.stdout
    rows = _rows(out / "log.csv")
    assert [int(r["iteration"]) for r in rows] == list(range(1, done + 2))
    assert sorted(c["node_id"] for c in json.loads((out / "collectors.json").read_text())["collectors"]) == sorted(
        cluster.worker_ids())
