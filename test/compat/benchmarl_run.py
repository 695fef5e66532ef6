"""A tiny BenchMARL experiment on vmas_ros, run with the BenchMARL venv's Python.

    .venv-benchmarl/bin/python -m test.compat.benchmarl_run --algorithm mappo --task navigation --out DIR

BenchMARL's own VMAS task, algorithm and model configurations (its YAML
defaults), shrunk to ``--frames`` frames, with ``vmas`` resolving to vmas_ros
through ``install_as_vmas()``. Prints one JSON line: frames trained, the run
folder, the checkpoint, and the class of the env BenchMARL stepped.
"""
from __future__ import annotations

import argparse
import json
import os

import vmas_ros

vmas_ros.install_as_vmas()  # before BenchMARL and TorchRL are imported

from benchmarl.algorithms import IppoConfig, MappoConfig  # noqa: E402
from benchmarl.environments import VmasTask  # noqa: E402
from benchmarl.experiment import Experiment, ExperimentConfig  # noqa: E402
from benchmarl.models.mlp import MlpConfig  # noqa: E402

ALGORITHMS = {"mappo": MappoConfig, "ippo": IppoConfig}


def run(algorithm: str, task: str, out: str, frames: int, seed: int) -> dict:
    config = ExperimentConfig.get_from_yaml()
    config.max_n_frames = frames
    config.on_policy_collected_frames_per_batch = frames // 2
    config.on_policy_n_envs_per_worker = 6
    config.on_policy_n_minibatch_iters = 1
    config.on_policy_minibatch_size = frames // 4
    config.evaluation = False
    config.loggers = []
    config.checkpoint_at_end = True
    os.makedirs(out, exist_ok=True)
    config.save_folder = out
    config.sampling_device = config.train_device = config.buffer_device = "cpu"
    experiment = Experiment(
        task=VmasTask[task.upper()].get_from_yaml(), algorithm_config=ALGORITHMS[algorithm].get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(), critic_model_config=MlpConfig.get_from_yaml(),
        seed=seed, config=config,
    )
    experiment.run()
    checkpoints = sorted(str(p) for p in experiment.folder_name.rglob("*.pt"))
    return {
        "frames": int(experiment.total_frames), "folder": str(experiment.folder_name), "checkpoints": checkpoints,
        "env_class": f"{type(experiment.test_env.base_env._env).__module__}"
        if hasattr(experiment, "test_env") else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--algorithm", choices=sorted(ALGORITHMS), default="mappo")
    parser.add_argument("--task", default="navigation", help="a BenchMARL VmasTask name, e.g. navigation, balance")
    parser.add_argument("--out", required=True)
    parser.add_argument("--frames", type=int, default=1200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(json.dumps(run(args.algorithm, args.task, args.out, args.frames, args.seed)))


if __name__ == "__main__":
    main()
