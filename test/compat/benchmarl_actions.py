"""BenchMARL's own deterministic actions on observations from stepping the task's env (BenchMARL's venv).

    .venv-benchmarl/bin/python -m test.compat.benchmarl_actions CHECKPOINT OUT_DIR [--steps N]

Reloads the run with ``Experiment.reload_from_file``, rolls its env out for
``--steps`` steps with ``experiment.policy`` under
``ExplorationType.DETERMINISTIC``, and writes ``observations.npy``
``[frames, n_agents, obs]`` and ``actions.npy`` ``[frames, n_agents, act]``
(the actions BenchMARL took on exactly those observations).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import vmas_ros

vmas_ros.install_as_vmas()

import torch  # noqa: E402
from benchmarl.experiment import Experiment  # noqa: E402
from torchrl.envs.utils import ExplorationType, set_exploration_type  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("checkpoint")
    parser.add_argument("out")
    parser.add_argument("--steps", type=int, default=15)
    args = parser.parse_args()
    experiment = Experiment.reload_from_file(args.checkpoint, experiment_patch={"loggers": []})
    (group,) = experiment.group_map
    env = experiment.env_func()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = env.rollout(max_steps=args.steps, policy=experiment.policy, break_when_any_done=False)
    obs = rollout[group, "observation"]
    actions = rollout[group, "action"]
    obs = obs.reshape(-1, *obs.shape[-2:]).numpy().astype(np.float32)
    actions = actions.reshape(-1, *actions.shape[-2:]).numpy().astype(np.float32)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "observations.npy", obs)
    np.save(out / "actions.npy", actions)
    print(json.dumps({"frames": int(obs.shape[0]), "observation_shape": list(obs.shape),
                      "action_shape": list(actions.shape)}))


if __name__ == "__main__":
    main()
