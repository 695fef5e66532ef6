"""Actor and critic networks for the paper's four PPO variants.

Every network maps ``[..., n_agents, obs_size]`` to ``[..., n_agents, out]``, so the
policy, the critic and the ONNX export all see the same tensor layout whatever
the algorithm. Hidden layers are tanh MLPs (the paper: two layers, tanh).

Which network an algorithm uses is set by :class:`NetworkLayout`:

* a *centralised* actor (CPPO) is one "super-agent": a single MLP from all agents'
  observations, concatenated, to all agents' action parameters;
* a *decentralised* actor or critic maps each agent's own observation, with one
  set of weights for all agents (``share=True``: IPPO, MAPPO) or one per agent
  (HetIPPO); built on TorchRL's ``MultiAgentMLP``;
* a *centralised* critic (CPPO, MAPPO) reads every agent's observation; with
  shared weights it gives every agent the same team value.
"""
from __future__ import annotations

from dataclasses import dataclass
import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.modules import MLP, MultiAgentMLP, ProbabilisticActor, TanhNormal

__all__ = ["NetworkLayout", "SuperAgentMLP", "build_actor_network", "build_policy", "build_critic",
           "deterministic_action", "GROUP", "OBS_KEY", "ACTION_KEY", "LOG_PROB_KEY", "VALUE_KEY"]

GROUP = "agents"
OBS_KEY = (GROUP, "observation")
ACTION_KEY = (GROUP, "action")
LOG_PROB_KEY = (GROUP, "action_log_prob")
VALUE_KEY = (GROUP, "state_value")
LOC_KEY = (GROUP, "loc")
SCALE_KEY = (GROUP, "scale")


@dataclass(frozen=True)
class NetworkLayout:
    """Who sees what and who shares weights: the only difference between the four algorithms."""

    centralised_actor: bool
    share_actor: bool
    centralised_critic: bool
    share_critic: bool


class SuperAgentMLP(nn.Module):
    """One MLP from all agents' observations to all agents' outputs (CPPO's actor).

    ``[..., n, obs] -> flatten -> MLP -> [..., n, out]``: the multi-agent problem
    seen as one agent with a joint observation and a joint action.
    """

    def __init__(self, n_agents: int, obs_size: int, out_size: int, depth: int, num_cells: int,
                 device: torch.device) -> None:
        super().__init__()
        self.n_agents, self.out_size = n_agents, out_size
        self.mlp = MLP(in_features=n_agents * obs_size, out_features=n_agents * out_size, depth=depth,
                       num_cells=num_cells, activation_class=nn.Tanh, device=device)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        out = self.mlp(observation.flatten(-2, -1))
        return out.unflatten(-1, (self.n_agents, self.out_size))


def _multi_agent_mlp(n_agents: int, in_size: int, out_size: int, centralised: bool, share: bool, depth: int,
                     num_cells: int, device: torch.device) -> nn.Module:
    return MultiAgentMLP(n_agent_inputs=in_size, n_agent_outputs=out_size, n_agents=n_agents,
                         centralized=centralised, share_params=share, device=device, depth=depth,
                         num_cells=num_cells, activation_class=nn.Tanh)


def build_actor_network(layout: NetworkLayout, n_agents: int, obs_size: int, action_size: int, depth: int,
                        num_cells: int, device: torch.device) -> nn.Module:
    """Observation ``[..., n, obs]`` to Gaussian parameters ``[..., n, 2 * action_size]`` (loc, then scale)."""
    if layout.centralised_actor:
        return SuperAgentMLP(n_agents, obs_size, 2 * action_size, depth, num_cells, device)
    return _multi_agent_mlp(n_agents, obs_size, 2 * action_size, False, layout.share_actor, depth, num_cells, device)


def build_policy(actor_network: nn.Module, low: torch.Tensor, high: torch.Tensor) -> ProbabilisticActor:
    """Stochastic policy: TanhNormal over the action box ``[low, high]`` (each ``[n_agents, act]``).

    TanhNormal keeps samples inside the bounds, so the env never sees an
    out-of-range action, and its deterministic action (tanh of the mean, rescaled)
    is what the ONNX export reproduces.
    """
    module = TensorDictModule(nn.Sequential(actor_network, NormalParamExtractor()),
                              in_keys=[OBS_KEY], out_keys=[LOC_KEY, SCALE_KEY])
    return ProbabilisticActor(
        module, in_keys={"loc": LOC_KEY, "scale": SCALE_KEY}, out_keys=[ACTION_KEY],
        distribution_class=TanhNormal, distribution_kwargs={"low": low, "high": high},
        return_log_prob=True, log_prob_key=LOG_PROB_KEY,
    )


def build_critic(layout: NetworkLayout, n_agents: int, obs_size: int, depth: int, num_cells: int,
                 device: torch.device) -> TensorDictModule:
    """State value per agent ``[..., n, 1]`` under ``("agents", "state_value")``."""
    net = _multi_agent_mlp(n_agents, obs_size, 1, layout.centralised_critic, layout.share_critic, depth,
                           num_cells, device)
    return TensorDictModule(net, in_keys=[OBS_KEY], out_keys=[VALUE_KEY])


def deterministic_action(actor_network: nn.Module, observation: torch.Tensor, low: torch.Tensor,
                         high: torch.Tensor) -> torch.Tensor:
    """The policy's deterministic action: TanhNormal's transformed mean, clipped to the bounds.

    Written with plain tensor ops (no distribution object) so that it traces to
    ONNX; it equals ``ProbabilisticActor`` under ``ExplorationType.DETERMINISTIC``.
    """
    params = actor_network(observation)
    loc = params[..., : params.shape[-1] // 2]
    action = (high + low) / 2 + (high - low) / 2 * torch.tanh(loc)
    return torch.maximum(torch.minimum(action, high), low)

