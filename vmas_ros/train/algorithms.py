"""The paper's four PPO variants as network layouts, plus TorchRL's PPO loss around them.

The VMAS paper (Figure 3) compares four PPO algorithms that differ only in
which observations each network sees and whether agents share weights:

=========  ======================  ======================  ================
algorithm  actor                   critic                  parameter sharing
=========  ======================  ======================  ================
CPPO       centralised (one        centralised             one super-agent
           super-agent)
MAPPO      decentralised           centralised             shared
IPPO       decentralised           decentralised           shared
HetIPPO    decentralised           decentralised           none
=========  ======================  ======================  ================

The PPO maths is TorchRL's (``ClipPPOLoss`` with its GAE value estimator); this
module only wires keys and networks.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict

import torch
from torch import nn
from torchrl.modules import ProbabilisticActor
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from vmas_ros.train.config import TrainConfig
from vmas_ros.train.models import (ACTION_KEY, GROUP, LOG_PROB_KEY, VALUE_KEY, NetworkLayout, build_actor_network,
                                   build_critic, build_policy)

__all__ = ["ALGORITHMS", "PPOAgent", "build_agent"]

ALGORITHMS: Dict[str, NetworkLayout] = {
    "cppo": NetworkLayout(centralised_actor=True, share_actor=True, centralised_critic=True, share_critic=True),
    "mappo": NetworkLayout(centralised_actor=False, share_actor=True, centralised_critic=True, share_critic=True),
    "ippo": NetworkLayout(centralised_actor=False, share_actor=True, centralised_critic=False, share_critic=True),
    "hetippo": NetworkLayout(centralised_actor=False, share_actor=False, centralised_critic=False,
                             share_critic=False),
}


@dataclass
class PPOAgent:
    """Everything trained: the actor network (what gets exported), the policy, critic, loss and optimiser."""

    actor_network: nn.Module
    policy: ProbabilisticActor
    critic: nn.Module
    loss: ClipPPOLoss
    optimizer: torch.optim.Optimizer
    low: torch.Tensor
    high: torch.Tensor


def build_agent(config: TrainConfig, n_agents: int, obs_size: int, action_size: int, low: torch.Tensor,
                high: torch.Tensor) -> PPOAgent:
    """Networks, TanhNormal policy, ClipPPOLoss with GAE and Adam for ``config.algorithm``.

    ``low``/``high`` are the action bounds, ``[n_agents, action_size]``.
    """
    layout = ALGORITHMS[config.algorithm]
    device = torch.device(config.device)
    low, high = low.to(device), high.to(device)
    actor_network = build_actor_network(layout, n_agents, obs_size, action_size, config.depth, config.num_cells,
                                        device)
    policy = build_policy(actor_network, low, high)
    critic = build_critic(layout, n_agents, obs_size, config.depth, config.num_cells, device)
    loss = ClipPPOLoss(actor_network=policy, critic_network=critic, clip_epsilon=config.clip_epsilon,
                       entropy_bonus=config.entropy_coef > 0, entropy_coeff=config.entropy_coef,
                       critic_coeff=config.critic_coef, loss_critic_type="smooth_l1",
                       normalize_advantage=config.normalize_advantage,
                       # advantages [..., n_agents, 1]: standardise each agent's separately
                       normalize_advantage_exclude_dims=(-2,))
    # per-agent rewards, dones and values live in the "agents" group
    loss.set_keys(reward=(GROUP, "reward"), action=ACTION_KEY, sample_log_prob=LOG_PROB_KEY, value=VALUE_KEY,
                  done=(GROUP, "done"), terminated=(GROUP, "terminated"))
    loss.make_value_estimator(ValueEstimators.GAE, gamma=config.gamma, lmbda=config.lmbda)
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    return PPOAgent(actor_network, policy, critic, loss, optimizer, low, high)
