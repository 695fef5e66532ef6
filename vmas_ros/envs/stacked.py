"""The stacked step: every agent's action in, every agent's results out, one tensor each.

``Environment.step`` given one ``[n_agents, num_envs, size]`` action tensor
returns stacked results instead of VMAS's lists: observations ``[n_agents,
num_envs, obs_size]``, rewards ``[n_agents, num_envs]`` and infos as one dict
of ``[n_agents, num_envs, ...]`` tensors. A swarm of thousands of agents then
costs no Python call per agent in the environment: the lists alone (one
tensor per agent, one dict per agent) take longer than a sparse swarm's
physics.

What makes it fast is on each side of the step:

* actions: when every agent is a holonomic policy agent that the scenario
  does not process (the common swarm), the stacked forces go into the
  world's action block in one copy, and each agent's ``action.u`` is its
  row, taken only if someone reads it (``ActionBlock.publish_u``). Other
  worlds get their actions agent by agent, as with the list;
* results: scenarios that can compute every agent's result at once say so
  with ``stacked_observations``/``stacked_rewards``/``stacked_infos``
  (:class:`~vmas_ros.simulator.scenario.BaseScenario`); for the others the
  per-agent results are stacked here. Observations that are dicts or differ
  in shape between agents cannot be stacked: they come as the list; infos
  likewise.
"""
from __future__ import annotations

from typing import Callable, List, Optional

import torch
from torch import Tensor

from vmas_ros.simulator.dynamics.holonomic import Holonomic
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import TorchUtils

__all__ = ["set_stacked_forces", "stackable", "step_results"]


def _holonomic_swarm(env) -> bool:
    """Whether the stacked actions can be every agent's force as they are (see the module docstring);
    fixed for the env's life, so worked out once."""
    cached = env.__dict__.get("_holonomic_swarm")
    if cached is None:
        world, scenario = env.world, env.scenario
        agents = env.agents
        cached = (
            env.continuous_actions and len(agents) == len(world.agents) and len(agents) > 0
            and all(a is b for a, b in zip(agents, world.agents))
            and isinstance(scenario, BaseScenario)
            and type(scenario).process_action is BaseScenario.process_action
            and all(type(a.dynamics) is Holonomic and a.action_script is None for a in agents)
            # (action width, physical size, message width, multiplier is one, noise is added)
            and all(plan[:3] == (2, 2, 0) and plan[3] and not plan[4] for plan in env._action_plans())
        )
        env._holonomic_swarm = cached
    return cached


def set_stacked_forces(env, stacked: Tensor, commands: Optional[Callable[[Tensor, Tensor], Tensor]] = None) -> bool:
    """Apply ``stacked`` ``[A, B, 2]`` (checked, clamped) as every agent's force in one copy, if the world
    allows it; returns whether it did (otherwise the caller applies them agent by agent). ``commands``:
    what the agents execute instead, ``commands(stacked, into)`` writing it into the block's forces ``into``
    and returning it (a randomiser's delayed and lagged commands, in place of the copy)."""
    if stacked.requires_grad or not _holonomic_swarm(env):
        return False
    block = env.world._actions
    if block.loose:  # some agent holds a force of its own (one that needs gradients)
        return False
    forces = block.stacks()[0]
    if commands is None:
        forces.copy_(stacked)
    else:
        stacked = commands(stacked, forces)
    block.publish_u(stacked)
    return True


def stackable(env) -> bool:
    """Whether this step's actions went in as one block (:func:`set_stacked_forces`; ``_set_actions``
    withdraws the block first every step): then the scenario's per-agent ``process_action`` and dynamics
    calls are skipped, as they would do nothing more."""
    return env.world._actions.u_rows is not None


def _stack(values: List[Tensor]) -> Optional[Tensor]:
    """``values`` stacked, or None when they are not tensors of one shape."""
    if not values or not all(isinstance(v, Tensor) for v in values):
        return None
    shape = values[0].shape
    if any(v.shape != shape for v in values):
        return None
    return torch.stack(values)


def _stack_infos(infos: List[dict]):
    """Per-agent info dicts as one dict of stacked tensors, or the list when they differ in keys or shapes."""
    if not infos:
        return {}
    keys = list(infos[0])
    if any(list(info) != keys for info in infos):
        return infos
    stacked = {}
    for key in keys:
        value = _stack([info[key] for info in infos])
        if value is None:
            return infos
        stacked[key] = value
    return stacked


def step_results(env) -> tuple:
    """The stacked step's return: ``obs, rews, dones, infos`` (``obs, rews, terminated, truncated, infos``
    with ``terminated_truncated``), every agent's stacked (see the module docstring). Rewards first, as the
    list collection does: scenarios may cache work in ``reward``."""
    scenario, agents = env.scenario, env.agents
    hook = getattr(scenario, "stacked_rewards", None)
    rewards = hook() if hook is not None else None
    if rewards is None:  # each copied as it comes, unless fresh: a scenario may reuse one buffer for all agents
        fresh = scenario.fresh_rewards
        rewards = torch.stack([scenario.reward(agent) if fresh else scenario.reward(agent).clone() for agent in agents])
    else:
        rewards = rewards.clone()
    hook = getattr(scenario, "stacked_observations", None)
    obs = hook() if hook is not None else None
    if obs is None:
        per_agent = [scenario.observation(agent) for agent in agents]
        obs = _stack(per_agent)
        if obs is None:
            obs = per_agent if scenario.fresh_observations else [TorchUtils.recursive_clone(o) for o in per_agent]
    if env.randomiser is not None and env.randomiser.on_observations:  # (tensor observations only)
        obs = env.randomiser.observations(obs) if isinstance(obs, Tensor) else env.randomiser.observation_list(obs)
    if isinstance(scenario, BaseScenario):
        scenario.env_observations_handed_out()
    hook = getattr(scenario, "stacked_infos", None)
    infos = hook() if hook is not None else None
    if infos is None:
        infos = _stack_infos([scenario.info(agent) for agent in agents])
    if env.terminated_truncated:
        terminated, truncated = env._done()
        return obs, rewards, terminated, truncated, infos
    return obs, rewards, env._done(), infos
