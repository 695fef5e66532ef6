"""The training loop: collect a batch from all envs, GAE, PPO epochs, log, checkpoint; evaluate and export at the end.

One iteration steps ``num_envs`` envs ``frames_per_batch / num_envs`` times with
the stochastic policy (envs that finish are reset on the fly, the rest carry on
into the next iteration), computes advantages with TorchRL's GAE, then runs
``epochs`` passes of ClipPPOLoss over minibatches drawn without replacement.
The envs run in this process, or in ``collectors`` Ray actors when
``ray_address`` is set (see :mod:`vmas_ros.train.collection`); the learner
always stays here.

Output directory (``config.out``)::

    config.json         the configuration used (a resumed run rewrites it)
    log.csv             one row per iteration (see ``logs.LOG_COLUMNS``)
    collectors.json     where the envs ran (Ray node IDs) and each collector's frames/s
    learning_curve.png  mean episode reward against frames
    checkpoint.pt       every ``checkpoint_every`` iterations and at the end (resume from it)
    eval.json, eval.gif deterministic-policy evaluation, GIF of env 0
    policy.onnx/.json   exported deterministic policy (see ``export.py``)
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
from torchrl.envs.utils import ExplorationType, set_exploration_type

from vmas_ros.envs.make_env import make_env
from vmas_ros.envs.torchrl_env import TorchRLEnv
from vmas_ros.train.algorithms import PPOAgent, build_agent
from vmas_ros.train.checkpoint import CHECKPOINT_NAME, save_checkpoint
from vmas_ros.train.collection import Collection, LocalCollection
from vmas_ros.train.config import TrainConfig
from vmas_ros.train.export import describe_env, export_policy
from vmas_ros.train.logs import plot_learning_curve, write_csv
from vmas_ros.train.models import ACTION_KEY, OBS_KEY

__all__ = ["Trainer", "evaluate_policy"]


def _make_env(config: TrainConfig, num_envs: int, seed: int):
    return make_env(config.scenario, num_envs=num_envs, device=config.device, continuous_actions=True,
                    max_steps=config.max_steps, seed=seed, terminated_truncated=True,
                    randomisation=config.randomisation or None, **config.scenario_kwargs)


class Trainer:
    """Owns the env, the PPO agent and the run directory; ``run()`` trains to ``config.iterations``.

    Pass ``resume_state`` (a loaded checkpoint) to continue a run: weights,
    optimiser state, iteration counter, frame count and log history are restored;
    the envs restart from fresh resets (their physical state is not saved).
    """

    def __init__(self, config: TrainConfig, resume_state: Optional[Dict[str, Any]] = None,
                 progress: bool = True) -> None:
        self.config = config.validate()
        self.progress = progress
        self.out = Path(config.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.device = torch.device(config.device)
        start_iteration = int(resume_state["iteration"]) if resume_state else 0
        torch.manual_seed(config.seed + 7919 * start_iteration)
        # a resumed run gets fresh env randomness, not a replay of the first iterations
        self.env_seed = config.seed + 104729 * start_iteration
        on_ray = config.ray_address != "none"
        # on Ray the collectors own the envs; this process only needs one to read the spaces from
        self.env = _make_env(config, 1 if on_ray else config.num_envs, self.env_seed)
        self.env_info = describe_env(self.env)
        low = torch.tensor(self.env_info["action_low"], dtype=torch.float32)
        high = torch.tensor(self.env_info["action_high"], dtype=torch.float32)
        self.agent: PPOAgent = build_agent(config, len(self.env_info["agents"]), self.env_info["observation_size"],
                                           self.env_info["action_size"], low, high)
        self.iteration, self.frames = 0, 0
        self.history: List[Dict[str, float]] = []
        if resume_state is not None:
            self._restore(resume_state)
        self.buffer = ReplayBuffer(storage=LazyTensorStorage(config.frames_per_batch, device=self.device),
                                   sampler=SamplerWithoutReplacement(), batch_size=config.minibatch_size)
        self.collection: Collection = self._start_collection() if on_ray else LocalCollection(
            TorchRLEnv(self.env), self.agent.policy, config.steps_per_batch)
        (self.out / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")

    def _start_collection(self) -> Collection:
        from vmas_ros.train.ray_collection import RayCollection, connect

        config = self.config
        self._ray_connected = connect(config.ray_address)
        env_kwargs = dict(scenario=config.scenario, num_envs=config.num_envs, continuous_actions=True,
                          max_steps=config.max_steps, seed=self.env_seed, terminated_truncated=True,
                          randomisation=config.randomisation or None, **config.scenario_kwargs)
        return RayCollection(env_kwargs, self.agent.policy, config.steps_per_batch, config.collectors,
                             config.collector_cpus, config.collector_device, self.device, config.ray_address)

    def close(self) -> None:
        """Stop the collectors (and leave Ray if this trainer joined it); safe to call twice."""
        self.collection.close()
        if getattr(self, "_ray_connected", False):
            import ray

            ray.shutdown()
            self._ray_connected = False

    # ------------------------------------------------------------- checkpoints
    def _restore(self, state: Dict[str, Any]) -> None:
        if state["env_info"] != self.env_info:
            raise ValueError(f"checkpoint was trained on {state['env_info']['agents']} with observation size "
                             f"{state['env_info']['observation_size']}; this env differs: {self.env_info['agents']} "
                             f"with {self.env_info['observation_size']} (same scenario and scenario_kwargs?)")
        for key in ("algorithm", "num_cells", "depth"):
            if state["config"][key] != getattr(self.config, key):
                raise ValueError(f"cannot resume: checkpoint has {key}={state['config'][key]!r}, "
                                 f"config has {getattr(self.config, key)!r}")
        self.agent.actor_network.load_state_dict(state["actor"])
        self.agent.critic.load_state_dict(state["critic"])
        self.agent.optimizer.load_state_dict(state["optimizer"])
        self.iteration, self.frames = int(state["iteration"]), int(state["frames"])
        self.history = [dict(row) for row in state["history"]]

    def save(self) -> Path:
        """Write ``checkpoint.pt`` (weights, optimiser, counters, log) to the output directory."""
        return save_checkpoint(self.out / CHECKPOINT_NAME, {
            "config": self.config.to_dict(), "env_info": self.env_info, "iteration": self.iteration,
            "frames": self.frames, "actor": self.agent.actor_network.state_dict(),
            "critic": self.agent.critic.state_dict(), "optimizer": self.agent.optimizer.state_dict(),
            "history": self.history,
        })

    # ---------------------------------------------------------------- collect
    def collect(self) -> tuple:
        """One batch ``[num_envs, steps_per_batch]`` and the returns of the episodes that ended in it."""
        return self.collection.collect()

    def write_collectors(self) -> Path:
        """``collectors.json``: where each collector ran and its frames/s so far."""
        path = self.out / "collectors.json"
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps({**self.collection.describe(), "iteration": self.iteration}, indent=2) + "\n")
        tmp.replace(path)
        return path

    # ------------------------------------------------------------------ train
    def update(self, batch: TensorDict) -> Dict[str, float]:
        """GAE over the batch, then ``epochs`` PPO passes; returns mean losses."""
        loss, config = self.agent.loss, self.config
        with torch.no_grad():
            loss.value_estimator(batch, params=loss.critic_network_params,
                                 target_params=loss.target_critic_network_params)
        self.buffer.empty()
        self.buffer.extend(batch.reshape(-1))
        totals: Dict[str, float] = {}
        count = 0
        params = list(loss.parameters())
        for _ in range(config.epochs):
            for _ in range(config.frames_per_batch // config.minibatch_size):
                values = loss(self.buffer.sample())
                total = values["loss_objective"] + values["loss_critic"] + values.get("loss_entropy", 0.0)
                total.backward()
                torch.nn.utils.clip_grad_norm_(params, config.max_grad_norm)
                self.agent.optimizer.step()
                self.agent.optimizer.zero_grad(set_to_none=True)
                for key in ("loss_objective", "loss_critic", "loss_entropy", "entropy"):
                    if key in values.keys():
                        totals[key] = totals.get(key, 0.0) + values[key].detach()
                count += 1
        return {key: float(value) / count for key, value in totals.items()}

    def iterate(self) -> Dict[str, float]:
        """One iteration: collect, update, log a row."""
        start = time.perf_counter()
        batch, episodes = self.collect()
        collected = time.perf_counter()
        losses = self.update(batch)
        self.collection.policy_updated()
        end = time.perf_counter()
        self.iteration += 1
        self.frames += self.config.frames_per_batch
        row = {
            "iteration": self.iteration, "frames": self.frames,
            "episode_reward_mean": float(episodes.mean()) if episodes.numel() else math.nan,
            "episodes": int(episodes.numel()),
            "step_reward_mean": float(batch.get(("next", "agents", "reward")).mean()),
            "loss_objective": losses.get("loss_objective", math.nan),
            "loss_critic": losses.get("loss_critic", math.nan),
            "loss_entropy": losses.get("loss_entropy", math.nan), "entropy": losses.get("entropy", math.nan),
            "seconds_collect": collected - start, "seconds_train": end - collected, "seconds": end - start,
            "frames_per_second": self.config.frames_per_batch / (collected - start),
        }
        self.history.append(row)
        return row

    def run(self, on_iteration: Optional[Callable[[Dict[str, float]], None]] = None) -> Dict[str, Any]:
        """Train until ``config.iterations``; then evaluate, render and export. Returns a summary."""
        from tqdm import tqdm

        config = self.config
        bar = tqdm(total=config.iterations, initial=self.iteration, disable=not self.progress,
                   desc=f"{config.algorithm} {config.scenario}", unit="it")
        while self.iteration < config.iterations:
            row = self.iterate()
            bar.update(1)
            bar.set_postfix(reward=f"{row['episode_reward_mean']:.3f}", step_reward=f"{row['step_reward_mean']:.4f}",
                            s=f"{row['seconds']:.1f}")
            write_csv(self.out / "log.csv", self.history)
            self.write_collectors()
            if self.iteration % config.checkpoint_every == 0:
                self.save()
            if on_iteration is not None:
                on_iteration(row)
        bar.close()
        return self.finish()

    def finish(self) -> Dict[str, Any]:
        """Final checkpoint, CSV, learning curve, evaluation (+ GIF) and ONNX export; stops the collectors."""
        config = self.config
        self.save()
        self.close()
        summary: Dict[str, Any] = {"out": str(self.out), "iterations": self.iteration, "frames": self.frames}
        if self.history:
            write_csv(self.out / "log.csv", self.history)
            plot_learning_curve(self.out / "learning_curve.png", self.history,
                                f"{config.algorithm.upper()} on {config.scenario}")
        if config.eval_episodes > 0:
            gif = self.out / "eval.gif" if config.gif else None
            result = evaluate_policy(self.agent, config, config.eval_episodes, gif)
            (self.out / "eval.json").write_text(json.dumps(result, indent=2) + "\n")
            summary["eval"] = result
        onnx_path, json_path = export_policy(self.agent.actor_network, self.env_info, config.scenario,
                                             config.scenario_kwargs, config.algorithm, self.out / "policy",
                                             randomisation=config.randomisation)
        summary["onnx"], summary["policy_json"] = str(onnx_path), str(json_path)
        return summary


@torch.no_grad()
def evaluate_policy(agent: PPOAgent, config: TrainConfig, episodes: int,
                    gif_path: Optional[Path] = None) -> Dict[str, Any]:
    """Run ``episodes`` parallel episodes of the deterministic policy (one ``max_steps`` episode each).

    An env's return stops at its first done, as in ``vmas-ros evaluate``. With
    ``gif_path`` env 0 is rendered every step (the same renderer as ``vmas-ros render``).
    """
    env = _make_env(config, episodes, config.seed + 1_000_003)
    tenv = TorchRLEnv(env)
    td = tenv.reset()
    returns = torch.zeros(episodes, device=env.device)
    alive = torch.ones(episodes, dtype=torch.bool, device=env.device)
    frames = [env.render(env_index=0)] if gif_path else []
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        for _ in range(config.max_steps):
            td = agent.policy(td.select(OBS_KEY))
            out = tenv.step(td.select(ACTION_KEY)).get("next")
            returns += torch.where(alive, out.get(("agents", "reward")).mean(dim=(1, 2)), 0.0)
            alive &= ~out.get("done").squeeze(-1)
            if gif_path:
                frames.append(env.render(env_index=0))
            td = out
            if not bool(alive.any()):
                break
    result = {"episodes": episodes, "episode_reward_mean": float(returns.mean()),
              "episode_reward_std": float(returns.std()) if episodes > 1 else 0.0,
              "done_fraction": float((~alive).float().mean())}
    if gif_path:
        from vmas_ros.simulator.video import save_frames

        save_frames(frames, gif_path, fps=10)
        result["gif"] = str(gif_path)
    return result
