"""The vectorized multi-agent environment (VMAS 1.5 ``Environment`` API).

``Environment`` steps ``num_envs`` copies of a scenario at once. Observations,
rewards and infos are lists (or dicts by agent name) of tensors whose first
dimension is the env. Each instance keeps its own random number generator
state, so two envs built with the same seed replay each other exactly, and
other code using torch's global RNG does not disturb them.
"""
from __future__ import annotations

from functools import partial
from typing import Dict, List, Optional, Sequence, Union

import numpy as np
import torch
from gymnasium import spaces
from torch import Tensor

from vmas_ros.compat.spaces import space_types
from vmas_ros.envs import actions as act
from vmas_ros.envs import stacked as stacked_step
from vmas_ros.envs.limits import check_world_size
from vmas_ros.envs.memory import check_memory
from vmas_ros.envs.random_streams import OwnRandomStreams
from vmas_ros.envs.randomisation import Randomisation
from vmas_ros.envs.randomiser import CommandsRefused, Randomiser
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import TorchUtils, as_index_tensor

__all__ = ["Environment"]


#: up to this many action elements (agents x envs x components) the range check clamps and compares
FEW_ACTION_ELEMENTS = 4096


class Environment(OwnRandomStreams):
    """A batch of ``num_envs`` environments of one scenario, stepped together."""

    #: VMAS's render modes and vectorised flag (``rgb_array`` frames are drawn headless, ``human`` too)
    metadata = {"render.modes": ["human", "rgb_array"], "runtime.vectorized": True}

    def __init__(
        self,
        scenario: BaseScenario,
        num_envs: int = 32,
        device="cpu",
        max_steps: Optional[int] = None,
        continuous_actions: bool = True,
        seed: Optional[int] = None,
        dict_spaces: bool = False,
        multidiscrete_actions: bool = False,
        clamp_actions: bool = False,
        grad_enabled: bool = False,
        terminated_truncated: bool = False,
        randomisation: Union[Randomisation, dict, None] = None,
        **kwargs,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive int, got {num_envs!r}")
        kwargs.update(check_world_size(num_envs, kwargs))  # before make_world allocates anything (envs/limits.py)
        if max_steps is not None and (not isinstance(max_steps, int) or max_steps < 1):
            raise ValueError(f"max_steps must be None or a positive int, got {max_steps!r}")
        if multidiscrete_actions and continuous_actions:
            raise ValueError("multidiscrete_actions=True needs continuous_actions=False")
        self.scenario = scenario
        self.num_envs = num_envs
        self._device = torch.device(device)
        self.max_steps = max_steps
        self.continuous_actions = continuous_actions
        self.dict_spaces = dict_spaces
        self.multidiscrete_actions = multidiscrete_actions
        self.clamp_action = clamp_actions
        self.grad_enabled = grad_enabled
        self.terminated_truncated = terminated_truncated
        self._rng_state: Optional[dict] = None
        self._seed_rng(0 if seed is None else seed)
        with self._own_rng():
            self.world = scenario.env_make_world(num_envs, self.device, **kwargs)
        check_memory(self.world, scenario)  # before the first reset or step allocates (envs/memory.py)
        self.agents = self.world.policy_agents
        self.n_agents = len(self.agents)
        config = Randomisation.from_dict(randomisation)  # (envs/randomisation.py) off unless asked for
        self.randomiser = Randomiser(self, config) if config.active() else None
        self.steps = torch.zeros(num_envs, device=self.device)
        observations = self.reset()
        self.action_space = self.get_action_space()
        self.observation_space = self.get_observation_space(observations)

    # -------------------------------------------------------------- step counts
    @property
    def steps(self) -> Tensor:
        """``[num_envs]`` float: steps taken since each env's last reset (as VMAS's ``env.steps``).

        A step only counts itself; the tensor is brought up to date when read
        (one op then, instead of one in every step). Writes into the tensor
        read, and assignments, hold as with a plain attribute.
        """
        if self._steps_pending:
            self._steps = self._steps + self._steps_pending
            self._steps_pending = 0
        return self._steps

    @steps.setter
    def steps(self, value: Tensor) -> None:
        self._steps, self._steps_pending = value, 0

    # -------------------------------------------------------------------- reset
    def reset(self, seed: Optional[int] = None, return_observations: bool = True, return_info: bool = False, return_dones: bool = False):
        """Reset every env; returns the observations (and infos/dones if asked)."""
        if seed is not None:
            self.seed(seed)
        with self._own_rng():
            self.scenario.env_reset_world_at(None)
            if self.randomiser is not None:
                self.randomiser.draw(None)
            self.steps = torch.zeros(self.num_envs, device=self.device)
            result = self._collect(return_observations, False, return_info, return_dones)
        return result[0] if result and len(result) == 1 else result

    def reset_at(self, index, return_observations: bool = True, return_info: bool = False, return_dones: bool = False):
        """Reset some envs: ``index`` is an int, a sequence/tensor of ints or a [num_envs] bool mask."""
        indices = as_index_tensor(index, self.num_envs, self.device)
        with self._own_rng():
            if indices.numel():
                if isinstance(index, int):
                    self.scenario.env_reset_world_at(int(indices[0]))
                elif self.scenario.supports_batched_reset:
                    self.scenario.env_reset_world_at(indices)
                else:  # VMAS scenarios take one int at a time
                    for i in indices.tolist():
                        self.scenario.env_reset_world_at(i)
                if self.randomiser is not None:
                    self.randomiser.draw(indices)
                self.steps[indices] = 0
            result = self._collect(return_observations, False, return_info, return_dones)
        return result[0] if result and len(result) == 1 else result

    # --------------------------------------------------------------------- step
    def step(self, actions: Union[Sequence, Dict, Tensor]):
        """Apply one action per agent to every env and advance the world by one step.

        ``actions``: a list with one ``[num_envs, size]`` tensor per agent, a dict
        of them by agent name (as VMAS takes), or all of them stacked in one
        ``[n_agents, num_envs, size]`` tensor (validated at once; for many agents).

        Returns ``obs, rews, dones, infos`` (or ``obs, rews, terminated, truncated,
        infos`` with ``terminated_truncated=True``): lists (or dicts by name) of
        per-agent tensors, or, for stacked actions, stacked results: ``obs``
        ``[n_agents, num_envs, obs_size]``, ``rews`` ``[n_agents, num_envs]``, infos
        one dict of ``[n_agents, num_envs, ...]`` (:mod:`vmas_ros.envs.stacked`).
        """
        is_stacked = isinstance(actions, Tensor)
        actions = self._ordered_actions(actions)
        # torch's streams and the grad mode swapped without context managers: at one env, two of them
        # cost as much as the physics
        callers_rng = self._swap_torch_rng(None)
        callers_grad = torch.is_grad_enabled()
        if callers_grad != self.grad_enabled:
            torch.set_grad_enabled(self.grad_enabled)
        try:
            self._set_actions(actions)
            if not stacked_step.stackable(self):
                for agent in self.world.agents:
                    self.scenario.env_process_action(agent)
            self.scenario.pre_step()
            self.world.step()
            self.scenario.post_step()
            self._steps_pending += 1
            if is_stacked:
                return stacked_step.step_results(self)
            return self._collect(True, True, True, True)
        finally:
            if callers_grad != self.grad_enabled:
                torch.set_grad_enabled(callers_grad)
            self._swap_torch_rng(callers_rng)

    def _ordered_actions(self, actions):
        if isinstance(actions, Tensor):  # every agent's action stacked: checked in _set_actions
            return actions
        if isinstance(actions, dict):
            names = [a.name for a in self.agents]
            missing = [n for n in names if n not in actions]
            unknown = [k for k in actions if k not in names]
            if missing or unknown:
                raise ValueError(f"action dict must have exactly the agents {names}; missing {missing}, unknown {unknown}")
            return [actions[n] for n in names]
        if not isinstance(actions, (list, tuple)):
            raise ValueError(f"actions must be a list (one per agent), a dict by agent name or one stacked "
                             f"[n_agents, num_envs, size] tensor, got {type(actions).__name__}")
        if len(actions) != self.n_agents:
            raise ValueError(f"expected actions for {self.n_agents} agents, got {len(actions)}")
        return list(actions)

    def _action_plans(self) -> list:
        """Per policy agent, what turning its action into ``action.u``/``c`` involves; fixed for the env's life.

        (action width, physical size, message width, multiplier is one, noise is added): computed once
        because each is a few Python calls per agent and step otherwise.
        """
        plans = self.__dict__.get("_plans")
        if plans is None:
            plans = self._plans = [
                (self.get_agent_action_size(agent), agent.action_size,
                 self.world.dim_c if not agent.silent and self.world.dim_c > 0 else 0,
                 all(float(v) == 1 for v in act.per_component(agent.action.u_multiplier)),
                 any(float(v) != 0 for v in act.per_component(agent.action.u_noise)))
                for agent in self.agents
            ]
        return plans

    def _set_actions(self, actions) -> None:
        """``actions``: a list with one per agent, or every agent's stacked ``[n_agents, num_envs, size]``."""
        stacked = None
        same_shapes = True
        if isinstance(actions, Tensor):
            stacked = act.to_stacked_actions(actions, self.n_agents, self.num_envs,
                                             [plan[0] for plan in self._action_plans()], self.device,
                                             self.continuous_actions)
            if not self.grad_enabled and stacked.requires_grad:
                stacked = stacked.detach()
            tensors = None  # one per agent only when needed: a swarm's thousand views cost more than its check
        elif self._plain_actions(actions):
            tensors = actions  # of one shape, range-checked as one below
        else:
            tensors = []
            for agent, action, plan in zip(self.agents, actions, self._action_plans()):
                action = act.to_action_tensor(action, agent.name, self.num_envs, plan[0], self.device,
                                              self.continuous_actions)
                if not self.grad_enabled and action.requires_grad:
                    action = action.detach()
                tensors.append(action)
            same_shapes = all(t.shape == tensors[0].shape for t in tensors)
        self.world._actions.publish_u(None)  # each agent's own u from here, unless all go in as one block
        if stacked is None and not tensors:  # every agent is scripted
            return
        if same_shapes:
            # one fused check (and one host read) for all agents; the slow per-agent path only names the culprit
            bounds = None
            if stacked is None:
                stacked = torch.stack(tensors)
            if stacked.dtype != torch.float32:
                stacked = stacked.float()
            low, high, low_ad, high_ad = self._stacked_bound_tensors()
            if self.clamp_action and self.continuous_actions:
                # NaN and inf are refused even when clamping: clamping would hide them as +-u_range
                if not bool(torch.isfinite(stacked).all()):
                    self._name_bad_action(stacked, tensors, unbounded=True)
                stacked = torch.clamp(stacked, low, high)
                tensors = None
            elif stacked.numel() <= FEW_ACTION_ELEMENTS:
                # few: two calls (clamping changes something, or meets a NaN, exactly when an action is out)
                if not torch.equal(torch.clamp(stacked, low, high), stacked):
                    self._name_bad_action(stacked, tensors)
            elif self.randomiser is not None and self.randomiser.on_commands:
                bounds = (low_ad, high_ad)  # checked in the randomiser's own pass over the commands
            else:
                # the extremes over the batch against the bounds: one pass over the actions (NaN
                # propagates through min/max and fails both comparisons)
                smallest, largest = torch.aminmax(stacked, dim=1)  # [A, D]
                if not bool(((smallest >= low_ad) & (largest <= high_ad)).all()):
                    self._name_bad_action(stacked, tensors)
            # what the agents execute: with a randomiser, the commands delayed and lagged
            commands = None if self.randomiser is None else partial(self.randomiser.commands, bounds=bounds)
            try:
                if stacked_step.set_stacked_forces(self, stacked, commands):
                    return
                if commands is not None:
                    stacked, tensors = commands(stacked), None
            except CommandsRefused:  # out of bounds: nothing was executed
                self._name_bad_action(stacked, tensors)
            tensors = list(stacked.unbind(0)) if tensors is None else tensors
        elif self.clamp_action and self.continuous_actions:
            self._name_bad_action(None, tensors, unbounded=True)
            lows, highs = self._stacked_bounds()
            tensors = [torch.maximum(torch.minimum(a.float(), high), low) for a, low, high in zip(tensors, lows, highs)]
        else:
            self._name_bad_action(None, tensors)
        for agent, action, plan in zip(self.agents, tensors, self._action_plans()):
            self._apply_action(agent, action, plan)

    def _name_bad_action(self, stacked: Optional[Tensor], tensors: Optional[list], unbounded: bool = False) -> None:
        """Raise naming the first agent whose action is out of its bounds (or, ``unbounded``, not finite);
        per agent, so only where a batched check found one or could not be made."""
        per_agent = list(stacked.unbind(0)) if tensors is None else tensors
        lows, highs = self._stacked_bounds()
        if unbounded:
            highs = [torch.full_like(low, float("inf")) for low in lows]
            lows = [-high for high in highs]
        kind = "continuous" if self.continuous_actions else "discrete"
        act.check_finite_and_range(per_agent, lows, highs, [a.name for a in self.agents], kind)

    def _plain_actions(self, actions: list) -> bool:
        """Whether ``actions`` need none of :func:`~vmas_ros.envs.actions.to_action_tensor`'s conversions
        (:func:`~vmas_ros.envs.actions.plain_actions`; the shape all of them must have is worked out once)."""
        shape = self.__dict__.get("_plain_action_shape", False)
        if shape is False:
            widths = {plan[0] for plan in self._action_plans()}
            shape = self._plain_action_shape = (torch.Size((self.num_envs, widths.pop()))
                                                if len(widths) == 1 and self.continuous_actions else None)
        return shape is not None and act.plain_actions(actions, shape, self.device)

    def _stacked_bound_tensors(self):
        """[A, 1, D] low and high of all agents' bounds, and the same as [A, D] (same-shape actions only)."""
        cached = getattr(self, "_stacked_bound_cache", None)
        if cached is None or cached[0] != self.device:
            lows, highs = self._stacked_bounds()
            low, high = torch.stack(lows).unsqueeze(1), torch.stack(highs).unsqueeze(1)
            cached = self._stacked_bound_cache = (self.device, low, high, low[:, 0], high[:, 0])
        return cached[1:]

    def _stacked_bounds(self):
        """Every agent's inclusive action bounds, computed once per env (they never change)."""
        cached = getattr(self, "_bounds_cache", None)
        if cached is None or cached[0] != self.device:
            bounds = [self._action_bounds(agent) for agent in self.agents]
            cached = self._bounds_cache = (self.device, [b[0] for b in bounds], [b[1] for b in bounds])
        return cached[1], cached[2]

    def _action_bounds(self, agent):
        """Inclusive [low, high] per action column, as tensors on the env's device."""
        comm = self.world.dim_c if not agent.silent and self.world.dim_c > 0 else 0
        if self.continuous_actions:
            u = agent.action.u_range_tensor
            low = torch.cat([-u, torch.zeros(comm, device=self.device)])
            high = torch.cat([u, torch.ones(comm, device=self.device)])
            return low, high
        space = self.get_agent_action_space(agent)
        if self.multidiscrete_actions:
            return torch.zeros(len(space.nvec), device=self.device), torch.tensor(space.nvec - 1, device=self.device, dtype=torch.float32)
        return torch.zeros(1, device=self.device), torch.tensor([space.n - 1], device=self.device, dtype=torch.float32)

    def _apply_action(self, agent, action: Tensor, plan: tuple) -> None:
        _, size, comm, multiplier_is_one, noisy = plan
        if self.continuous_actions:
            u = action if action.shape[1] == size else action[:, :size]
            c = action[:, size:] if comm else None
            if u.dtype != torch.float32:
                u = u.float()
            if c is not None and c.dtype != torch.float32:
                c = c.float()
        else:
            nvec = list(agent.discrete_action_nvec) + ([comm] if comm else [])
            choices = action.long() if self.multidiscrete_actions else act.unflatten_discrete(action[:, 0], nvec)
            u = act.discrete_to_continuous(choices[:, :size], agent.discrete_action_nvec, agent.action.u_range_tensor)
            c = None
            if comm:
                c = torch.nn.functional.one_hot(choices[:, size], comm).float()
        if not multiplier_is_one:
            u = u * agent.action.u_multiplier_tensor
        if noisy:
            u = u + torch.randn_like(u) * agent.action.u_noise_tensor
        agent.action._set_u(u)  # checked above: [num_envs, size] on the env's device
        if comm:
            if agent.c_noise > 0:
                c = c + torch.randn_like(c) * agent.c_noise
            agent.action.c = c

    # --------------------------------------------------------------- collection
    def _collect(self, get_obs: bool, get_rewards: bool, get_infos: bool, get_dones: bool, dict_agent_names: Optional[bool] = None):
        if not (get_obs or get_rewards or get_infos or get_dones):
            return None
        by_name = self.dict_spaces if dict_agent_names is None else dict_agent_names
        scenario, agents = self.scenario, self.agents
        # rewards first, then observations: scenarios may cache work in reward()
        rewards = obs = None
        if get_rewards:
            if scenario.fresh_rewards:
                rewards = [scenario.reward(agent) for agent in agents]
            else:  # each copied as it comes: a scenario may return a buffer it overwrites for the next agent
                rewards = [scenario.reward(agent).clone() for agent in agents]
        if get_obs and self.randomiser is not None and self.randomiser.on_observations:
            # the noise makes new tensors: from the scenario's stacked observations where it has them
            stacked = scenario.stacked_observations() if isinstance(scenario, BaseScenario) else None
            obs = (list(self.randomiser.observations(stacked, per_agent=True)) if stacked is not None
                   else self.randomiser.observation_list([scenario.observation(agent) for agent in agents]))
        elif get_obs:
            obs = [scenario.observation(agent) for agent in agents]
            if not scenario.fresh_observations:
                obs = [TorchUtils.recursive_clone(o) for o in obs]
        if (get_obs or get_rewards and scenario.fresh_rewards) and isinstance(scenario, BaseScenario):
            scenario.env_observations_handed_out()  # what went out uncopied is theirs: compute afresh next
        infos = [TorchUtils.recursive_clone(scenario.info(agent)) for agent in agents] if get_infos else None
        if by_name:
            names = [agent.name for agent in agents]
            rewards, obs, infos = (None if values is None else dict(zip(names, values))
                                   for values in (rewards, obs, infos))
        if self.terminated_truncated:
            terminated = truncated = None
            if get_dones:
                terminated, truncated = self._done()
            result = [obs, rewards, terminated, truncated, infos]
        else:
            dones = self._done() if get_dones else None
            result = [obs, rewards, dones, infos]
        return [value for value in result if value is not None]

    def get_from_scenario(self, get_observations: bool, get_rewards: bool, get_infos: bool, get_dones: bool, dict_agent_names: Optional[bool] = None):
        with self._own_rng():
            return self._collect(get_observations, get_rewards, get_infos, get_dones, dict_agent_names)

    def _done(self):
        terminated = self.scenario.done()
        if type(self.scenario).done is not BaseScenario.done:  # the default's is fresh; a scenario's may be kept
            terminated = terminated.clone()
        truncated = None if self.max_steps is None else self.steps >= self.max_steps
        if self.terminated_truncated:
            return terminated, (torch.zeros_like(terminated) if truncated is None else truncated)
        return terminated if truncated is None else terminated | truncated

    def done(self):
        with self._own_rng():
            return self._done()

    # ------------------------------------------------------------------- spaces
    # ``spaces = space_types()``: legacy gym's classes while install_as_vmas() is in effect, as VMAS
    # builds them (TorchRL's VmasEnv needs them), else gymnasium's (vmas_ros/compat/spaces.py)
    def get_agent_action_size(self, agent) -> int:
        comm = self.world.dim_c if not agent.silent and self.world.dim_c > 0 else 0
        if self.continuous_actions:
            return agent.action.action_size + comm
        if self.multidiscrete_actions:
            return agent.action_size + (1 if comm else 0)
        return 1

    def get_agent_action_space(self, agent) -> spaces.Space:
        spaces = space_types()
        comm = self.world.dim_c if not agent.silent and self.world.dim_c > 0 else 0
        if self.continuous_actions:
            u = agent.action.u_range_tensor.tolist()
            low = np.array([-x for x in u] + [0.0] * comm, dtype=np.float32)
            high = np.array(u + [1.0] * comm, dtype=np.float32)
            return spaces.Box(low=low, high=high, shape=(len(u) + comm,), dtype=np.float32)
        nvec = list(agent.discrete_action_nvec) + ([comm] if comm else [])
        if self.multidiscrete_actions:
            return spaces.MultiDiscrete(nvec)
        return spaces.Discrete(int(np.prod(nvec)))

    def get_action_space(self) -> spaces.Space:
        spaces = space_types()
        if self.dict_spaces:
            return spaces.Dict({a.name: self.get_agent_action_space(a) for a in self.agents})
        return spaces.Tuple([self.get_agent_action_space(a) for a in self.agents])

    def get_agent_observation_space(self, agent, obs) -> spaces.Space:
        spaces = space_types()
        if isinstance(obs, Tensor):
            return spaces.Box(low=-np.inf, high=np.inf, shape=tuple(obs.shape[1:]), dtype=np.float32)
        if isinstance(obs, dict):
            return spaces.Dict({k: self.get_agent_observation_space(agent, v) for k, v in obs.items()})
        raise TypeError(f"observation of agent {agent.name!r} must be a tensor or a dict of tensors, got {type(obs).__name__}")

    def get_observation_space(self, observations) -> spaces.Space:
        spaces = space_types()
        if self.dict_spaces:
            return spaces.Dict({a.name: self.get_agent_observation_space(a, observations[a.name]) for a in self.agents})
        return spaces.Tuple([self.get_agent_observation_space(a, o) for a, o in zip(self.agents, observations)])

    # ----------------------------------------------------------- random actions
    @property
    def device(self) -> torch.device:
        """The torch device every tensor of this env lives on (move with ``to``)."""
        return self._device

    @property
    def batch_dim(self) -> int:
        """VMAS's name for ``num_envs``: the number of batched environments."""
        return self.num_envs

    def get_random_action(self, agent) -> Tensor:
        with self._own_rng():
            if self.continuous_actions:
                low, high = self._action_bounds(agent)
                return low + (high - low) * torch.rand(self.num_envs, low.numel(), device=self.device)
            space = self.get_agent_action_space(agent)
            if self.multidiscrete_actions:
                nvec = torch.tensor(space.nvec, device=self.device)
                return (torch.rand(self.num_envs, len(space.nvec), device=self.device) * nvec).long()
            return torch.randint(0, int(space.n), (self.num_envs,), device=self.device)  # [B], as VMAS

    def get_random_actions(self) -> List[Tensor]:
        return [self.get_random_action(agent) for agent in self.agents]

    # ---------------------------------------------------------------- rendering
    def render(self, mode: str = "rgb_array", env_index: int = 0, agent_index_focus: Optional[int] = None,
               visualize_when_rgb: bool = False, plot_position_function=None, **kwargs):
        """Draw env ``env_index`` headless into an RGB array [H, W, 3] (no display needed); VMAS's keywords
        are taken (:func:`vmas_ros.envs.rendering.render_env` says how)."""
        from vmas_ros.envs.rendering import render_env

        return render_env(self, mode, env_index, agent_index_focus, plot_position_function, **kwargs)

    def to(self, device) -> None:
        self._device = torch.device(device)
        self.scenario.to(self.device)
        self.steps = self.steps.to(self.device)

    def close(self) -> None:
        """Nothing to release: rendering keeps no window open."""
