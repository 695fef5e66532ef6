"""One side of ``vmas-ros bench torchrl``: a multi-agent PPO loop through TorchRL's ``VmasEnv``.

Run as a fresh interpreter per side; it imports vmas_ros only for the
vmas_ros side (``install_as_vmas()``, so TorchRL's ``VmasEnv`` steps
vmas_ros), so the VMAS side pays nothing of ours:

    python torchrl_loop_side.py '{"side": "vmas_ros", "seed": 0}'

(``"config": {...}`` replaces entries of :data:`CONFIG`.)

The loop is the size and shape of TorchRL's multi-agent PPO tutorial:
navigation with 3 agents, 60 envs of 100 steps, 10 iterations of 6,000
frames, 30 epochs of minibatches of 400, a shared-parameter MAPPO policy
(TanhNormal over an MLP of 2 x 256) and a centralised critic, GAE, clipped
PPO, Adam at 3e-4. It prints JSON: seconds in the collector, in training,
and the last iteration's mean episode reward.
"""
from __future__ import annotations

import json
import os
import sys
import time

# run as a script, its folder (vmas_ros/bench/) would come first on sys.path and shadow libraries by its
# modules' names: leave it out
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [entry for entry in sys.path if os.path.abspath(entry or os.curdir) != _HERE]

CONFIG = dict(scenario="navigation", n_agents=3, max_steps=100, frames_per_batch=6_000, n_iters=10, num_epochs=30,
              minibatch_size=400, lr=3e-4, max_grad_norm=1.0, clip_epsilon=0.2, gamma=0.99, lmbda=0.9,
              entropy_eps=1e-4, depth=2, num_cells=256)


def main(side: str, seed: int, overrides: dict = None) -> dict:
    """The loop on ``side`` (``vmas_ros`` or ``vmas``); ``overrides`` replace entries of :data:`CONFIG`
    (tests run a smaller loop)."""
    started = time.perf_counter()
    unknown = sorted(set(overrides or {}) - set(CONFIG))
    if unknown:
        raise ValueError(f"unknown loop settings {unknown}; known: {sorted(CONFIG)}")
    if side == "vmas_ros":
        from vmas_ros.compat.install import install_as_vmas

        install_as_vmas()
    import torch
    from tensordict.nn import NormalParamExtractor, TensorDictModule
    from torch import nn
    from torchrl.collectors import Collector
    from torchrl.data.replay_buffers import ReplayBuffer
    from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
    from torchrl.data.replay_buffers.storages import LazyTensorStorage
    from torchrl.envs import RewardSum, TransformedEnv
    from torchrl.envs.libs.vmas import VmasEnv
    from torchrl.modules import MultiAgentMLP, ProbabilisticActor, TanhNormal
    from torchrl.objectives import ClipPPOLoss, ValueEstimators

    torch.manual_seed(seed)
    c = dict(CONFIG, **(overrides or {}))
    env = VmasEnv(scenario=c["scenario"], num_envs=c["frames_per_batch"] // c["max_steps"], continuous_actions=True,
                  max_steps=c["max_steps"], device="cpu", seed=seed, n_agents=c["n_agents"])
    env = TransformedEnv(env, RewardSum(in_keys=[env.reward_key], out_keys=[("agents", "episode_reward")]))
    observation = env.observation_spec["agents", "observation"].shape[-1]
    action = env.full_action_spec_unbatched[env.action_key]
    network = nn.Sequential(
        MultiAgentMLP(n_agent_inputs=observation, n_agent_outputs=2 * action.shape[-1], n_agents=env.n_agents,
                      centralised=False, share_params=True, depth=c["depth"], num_cells=c["num_cells"],
                      activation_class=nn.Tanh),
        NormalParamExtractor())
    module = TensorDictModule(network, in_keys=[("agents", "observation")], out_keys=[("agents", "loc"), ("agents", "scale")])
    policy = ProbabilisticActor(module=module, spec=env.full_action_spec_unbatched, in_keys=[("agents", "loc"), ("agents", "scale")],
                                out_keys=[env.action_key], distribution_class=TanhNormal,
                                distribution_kwargs={"low": action.space.low, "high": action.space.high},
                                return_log_prob=True)
    critic = TensorDictModule(
        MultiAgentMLP(n_agent_inputs=observation, n_agent_outputs=1, n_agents=env.n_agents, centralised=True,
                      share_params=True, depth=c["depth"], num_cells=c["num_cells"], activation_class=nn.Tanh),
        in_keys=[("agents", "observation")], out_keys=[("agents", "state_value")])
    collector = Collector(env, policy, frames_per_batch=c["frames_per_batch"],
                                  total_frames=c["frames_per_batch"] * c["n_iters"], device="cpu")
    buffer = ReplayBuffer(storage=LazyTensorStorage(c["frames_per_batch"]), sampler=SamplerWithoutReplacement(),
                          batch_size=c["minibatch_size"])
    loss = ClipPPOLoss(actor_network=policy, critic_network=critic, clip_epsilon=c["clip_epsilon"],
                       entropy_coeff=c["entropy_eps"], normalize_advantage=False)
    loss.set_keys(reward=env.reward_key, action=env.action_key, value=("agents", "state_value"),
                  done=("agents", "done"), terminated=("agents", "terminated"))
    loss.make_value_estimator(ValueEstimators.GAE, gamma=c["gamma"], lmbda=c["lmbda"])
    optimizer = torch.optim.Adam(loss.parameters(), c["lr"])

    collect_s = train_s = 0.0
    reward = float("nan")
    mark = time.perf_counter()
    for batch in collector:
        collect_s += time.perf_counter() - mark
        mark = time.perf_counter()
        # the agents' done flags, expanded from the env's (GAE reads them per agent)
        for key in ("done", "terminated"):
            batch.set(("next", "agents", key),
                      batch.get(("next", key)).unsqueeze(-1).expand(batch.get_item_shape(("next", env.reward_key))))
        with torch.no_grad():
            loss.value_estimator(batch, params=loss.critic_network_params, target_params=loss.target_critic_network_params)
        buffer.extend(batch.reshape(-1))
        for _ in range(c["num_epochs"]):
            for _ in range(c["frames_per_batch"] // c["minibatch_size"]):
                values = loss(buffer.sample())
                total = values["loss_objective"] + values["loss_critic"] + values["loss_entropy"]
                total.backward()
                torch.nn.utils.clip_grad_norm_(loss.parameters(), c["max_grad_norm"])
                optimizer.step()
                optimizer.zero_grad()
        collector.update_policy_weights_()
        done = batch.get(("next", "agents", "done"))
        reward = batch.get(("next", "agents", "episode_reward"))[done].mean().item()
        train_s += time.perf_counter() - mark
        mark = time.perf_counter()
    collector.shutdown()
    return {"side": side, "seed": seed, "collect_s": collect_s, "train_s": train_s,
            "in_process_s": time.perf_counter() - started, "last_mean_episode_reward": reward}


if __name__ == "__main__":
    options = json.loads(sys.argv[1])
    print(json.dumps(main(options["side"], options.get("seed", 0), options.get("config"))))
