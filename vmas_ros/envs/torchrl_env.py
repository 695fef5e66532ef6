"""``TorchRLEnv``: a vmas_ros ``Environment`` as a batched, multi-agent TorchRL env.

The layout follows TorchRL's multi-agent convention (the one its tutorials and
BenchMARL expect), so TorchRL's losses, value estimators and multi-agent networks
work on it unchanged::

    ("agents", "observation")   float32 [num_envs, n_agents, obs_size]
    ("agents", "action")        float32 [num_envs, n_agents, action_size]  (continuous)
                                int64   [num_envs, n_agents]               (discrete)
    ("agents", "reward")        float32 [num_envs, n_agents, 1]
    ("agents", "done" | "terminated" | "truncated")   bool [num_envs, n_agents, 1]
    "done" | "terminated" | "truncated"               bool [num_envs, 1]

All agents live in one group, so they must share observation and action sizes
(a ``ValueError`` says which agent differs). The env's batch is the
Environment's ``num_envs``: one TorchRL step steps every env at once, and partial
resets (TorchRL's ``"_reset"`` masks) become a single ``Environment.reset_at(mask)``.
"""
from __future__ import annotations

from typing import List, Optional

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from vmas_ros.envs.environment import Environment

__all__ = ["TorchRLEnv", "GROUP"]

#: name of the (single) agent group in the tensordicts
GROUP = "agents"


class TorchRLEnv(EnvBase):
    """TorchRL view of a vmas_ros ``Environment`` (batch size ``[num_envs]``).

    Args:
        env: the vectorized environment to wrap; its device becomes this env's device.
        **kwargs: passed on to ``torchrl.envs.EnvBase`` (e.g. ``allow_done_after_reset``).
    """

    def __init__(self, env: Environment, **kwargs) -> None:
        if not isinstance(env, Environment):
            raise TypeError(f"TorchRLEnv wraps a vmas_ros Environment, got {type(env).__name__}")
        if env.dict_spaces:
            raise ValueError("TorchRLEnv needs an Environment built with dict_spaces=False")
        if env.multidiscrete_actions:
            raise ValueError("TorchRLEnv supports continuous or Discrete actions, not multidiscrete_actions=True")
        kwargs.setdefault("device", env.device)
        kwargs.setdefault("batch_size", torch.Size([env.num_envs]))
        super().__init__(**kwargs)
        self.env = env
        self.agent_names: List[str] = [agent.name for agent in env.agents]
        self.n_agents = env.n_agents
        if self.n_agents == 0:
            raise ValueError("the scenario has no policy agents to control")
        self._make_specs()

    # ------------------------------------------------------------------- specs
    def _agent_sizes(self) -> tuple:
        """Shared observation and action sizes, or a ValueError naming the odd agent out."""
        obs_sizes = []
        for agent, space in zip(self.env.agents, self.env.observation_space):
            if not hasattr(space, "shape") or space.shape is None or len(space.shape) != 1:
                raise ValueError(f"agent {agent.name!r}: TorchRLEnv needs flat tensor observations, got space {space}")
            obs_sizes.append(int(space.shape[0]))
        act_sizes = [self.env.get_agent_action_size(agent) for agent in self.env.agents]
        for what, sizes in (("observation", obs_sizes), ("action", act_sizes)):
            if len(set(sizes)) != 1:
                detail = ", ".join(f"{n}={s}" for n, s in zip(self.agent_names, sizes))
                raise ValueError(f"all agents must have the same {what} size to form one group; got {detail}")
        return obs_sizes[0], act_sizes[0]

    def _make_specs(self) -> None:
        env, device = self.env, self.device
        b, n = env.num_envs, self.n_agents
        self.observation_size, self.action_size = self._agent_sizes()
        self.observation_spec = Composite(
            {GROUP: Composite({"observation": Unbounded(shape=(b, n, self.observation_size), dtype=torch.float32,
                                                        device=device)}, shape=(b, n), device=device)},
            shape=(b,), device=device,
        )
        if env.continuous_actions:
            lows, highs = zip(*(env._action_bounds(agent) for agent in env.agents))
            low = torch.stack(lows).to(device).expand(b, n, self.action_size).clone()
            high = torch.stack(highs).to(device).expand(b, n, self.action_size).clone()
            action = Bounded(low=low, high=high, shape=(b, n, self.action_size), dtype=torch.float32, device=device)
        else:
            choices = {int(env.get_agent_action_space(agent).n) for agent in env.agents}
            if len(choices) != 1:
                raise ValueError(f"all agents must have the same number of discrete actions, got {sorted(choices)}")
            action = Categorical(n=choices.pop(), shape=(b, n), dtype=torch.int64, device=device)
        self.action_spec = Composite({GROUP: Composite({"action": action}, shape=(b, n), device=device)},
                                     shape=(b,), device=device)
        self.reward_spec = Composite(
            {GROUP: Composite({"reward": Unbounded(shape=(b, n, 1), dtype=torch.float32, device=device)},
                              shape=(b, n), device=device)},
            shape=(b,), device=device,
        )
        flag = lambda *shape: Categorical(n=2, shape=shape, dtype=torch.bool, device=device)  # noqa: E731
        self.done_spec = Composite(
            {
                "done": flag(b, 1), "terminated": flag(b, 1), "truncated": flag(b, 1),
                GROUP: Composite({"done": flag(b, n, 1), "terminated": flag(b, n, 1), "truncated": flag(b, n, 1)},
                                 shape=(b, n), device=device),
            },
            shape=(b,), device=device,
        )

    # ------------------------------------------------------------ observations
    def _stack_obs(self, observations) -> torch.Tensor:
        return torch.stack([o.to(torch.float32) for o in observations], dim=1).to(self.device)

    def _output(self, obs: torch.Tensor, terminated: torch.Tensor, truncated: torch.Tensor,
                rewards: Optional[List[torch.Tensor]] = None) -> TensorDict:
        b, n = self.env.num_envs, self.n_agents
        terminated = terminated.reshape(b, 1).to(torch.bool)
        truncated = truncated.reshape(b, 1).to(torch.bool)
        done = terminated | truncated
        group = {
            "observation": obs,
            "done": done.unsqueeze(1).expand(b, n, 1).clone(),
            "terminated": terminated.unsqueeze(1).expand(b, n, 1).clone(),
            "truncated": truncated.unsqueeze(1).expand(b, n, 1).clone(),
        }
        if rewards is not None:
            group["reward"] = torch.stack([r.reshape(b) for r in rewards], dim=1).unsqueeze(-1).to(torch.float32)
        return TensorDict(
            {GROUP: TensorDict(group, batch_size=(b, n), device=self.device),
             "done": done, "terminated": terminated, "truncated": truncated},
            batch_size=(b,), device=self.device,
        )

    def _split_dones(self, dones) -> tuple:
        """(terminated, truncated) from the Environment's step output.

        With ``terminated_truncated=False`` the Environment only returns their
        union; truncation is then recomputed from the step counter, so an env
        that terminates exactly on its last step is counted as truncated.
        """
        if self.env.terminated_truncated:
            return dones
        done = dones[0]
        if self.env.max_steps is None:
            return done, torch.zeros_like(done)
        truncated = self.env.steps >= self.env.max_steps
        return done & ~truncated, truncated & done

    # ----------------------------------------------------------------- EnvBase
    def _reset(self, tensordict: Optional[TensorDictBase] = None, **kwargs) -> TensorDictBase:
        """Reset the envs selected by the ``"_reset"`` masks (all when there are none), in one call."""
        mask = None
        if tensordict is not None:
            for key in ("_reset", (GROUP, "_reset")):
                value = tensordict.get(key, None)
                if value is not None:
                    value = value.reshape(self.env.num_envs, -1).any(-1)
                    mask = value if mask is None else mask | value
        if mask is None or bool(mask.all()):
            obs = self.env.reset()
        else:
            obs = self.env.reset_at(mask.to(self.env.device))
        zeros = torch.zeros(self.env.num_envs, dtype=torch.bool, device=self.device)
        return self._output(self._stack_obs(obs), zeros, zeros)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get((GROUP, "action"))
        if self.env.continuous_actions:
            actions = list(action.unbind(1))
        else:
            actions = [a.reshape(self.env.num_envs, 1) for a in action.unbind(1)]
        obs, rewards, *dones, _infos = self.env.step(actions)
        terminated, truncated = self._split_dones(dones)
        return self._output(self._stack_obs(obs), terminated, truncated, rewards)

    def _set_seed(self, seed: Optional[int]) -> None:
        self.env.seed(seed)

    def render(self, env_index: int = 0, **kwargs):
        """Headless RGB frame [H, W, 3] of env ``env_index`` (see ``Environment.render``)."""
        return self.env.render(mode="rgb_array", env_index=env_index, **kwargs)
