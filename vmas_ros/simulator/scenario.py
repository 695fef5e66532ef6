"""BaseScenario: what a task defines (VMAS 1.5's scenario interface).

A scenario builds a :class:`World` in ``make_world`` and says how to reset it,
what each agent observes and earns, and when an env is done. Every method
works on all envs at once: tensors have the batch dimension first.
"""
from __future__ import annotations

import abc
from typing import Any, Callable, List, Optional

import torch
from torch import Tensor

from vmas_ros.simulator.observation_layout import ObservationLayout
from vmas_ros.simulator.utils import INITIAL_VIEWER_SIZE, VIEWER_DEFAULT_ZOOM

__all__ = ["BaseScenario"]


class BaseScenario(abc.ABC):
    """Subclass this and implement make_world, reset_world_at, observation and reward."""

    #: Set True in scenarios whose ``reset_world_at`` accepts a 1-D tensor of env
    #: indices; the environment then resets many envs in one call instead of one by one.
    supports_batched_reset: bool = False
    #: Set True in scenarios whose ``observation`` returns tensors it never writes to
    #: again (computed fresh, or views of a result computed fresh for the step): the
    #: environment then hands them out without the defensive copy it makes of VMAS
    #: scenarios' observations, which may be buffers the scenario updates in place.
    fresh_observations: bool = False
    #: Set True in scenarios whose ``reward`` returns each agent a tensor of its own (not one shared
    #: by agents) that the scenario never writes to again: the environment then hands the rewards out
    #: without the copy it makes of VMAS scenarios' rewards.
    fresh_rewards: bool = False

    def __init__(self) -> None:
        self._world = None
        self._outputs = None  # the batched_outputs hook as the engine runs it, when defined
        #: how many collections have handed observations out: results cached for a state are computed
        #: afresh for the next collection, so that two collections never share memory
        self.env_observations_handed_out_count = 0
        self.viewer_size = INITIAL_VIEWER_SIZE
        self.viewer_zoom = VIEWER_DEFAULT_ZOOM
        self.render_origin = (0.0, 0.0)
        self.plot_grid = False
        self.grid_spacing = 0.1
        self.visualize_semidims = True

    @property
    def world(self):
        if self._world is None:
            raise RuntimeError("the scenario has no world yet: make_world must create and return it")
        return self._world

    def to(self, device) -> None:
        for name, value in list(self.__dict__.items()):
            if isinstance(value, Tensor):
                self.__dict__[name] = value.to(device)
        self.world.to(device)

    # -- called by the environment; do not override --------------------------
    def env_make_world(self, batch_dim: int, device, **kwargs):
        self._world = self.make_world(batch_dim, device, **kwargs)
        if self.batched_outputs is not None:
            from vmas_ros.simulator.compiling import StateFunction

            self._outputs = StateFunction(self._world, self.batched_outputs)
        return self._world

    def env_observations_handed_out(self) -> None:
        # observations that are views of batched_outputs' result go out without a copy: the next
        # collection computes afresh, so two collections never share memory
        if self._outputs is not None:
            self._outputs.forget()
        self.env_observations_handed_out_count += 1

    def env_reset_world_at(self, env_index) -> None:
        self.world.reset(env_index)
        self.reset_world_at(env_index)

    def env_process_action(self, agent) -> None:
        if agent.action_script is not None:
            agent.action_callback(self.world)
        self.process_action(agent)
        agent.dynamics.check_and_process_action()

    # -- to implement ---------------------------------------------------------
    @abc.abstractmethod
    def make_world(self, batch_dim: int, device, **kwargs):
        """Create the World, add agents/landmarks/joints, return it."""

    @abc.abstractmethod
    def reset_world_at(self, env_index: Optional[int] = None) -> None:
        """Reset env ``env_index``, or every env when it is None."""

    # -- optional: state-wide outputs ------------------------------------------
    #: Optional: define as a method ``batched_outputs(self, q, v)`` computing, from the state at once,
    #: everything the rewards, observations and dones read. ``q``, ``v``: every entity's (x, y, angle)
    #: and (vx, vy, angular velocity), each ``[3, n_entities, B]`` in ``world.entities`` order
    #: (landmarks, then agents, each as added; see ``World.planar_state``). Return any tensors (a
    #: tuple, a dict). It must be a pure function of its arguments and of settings fixed at
    #: ``make_world``: the engine decides when it runs and may compile it with the physics. Read the
    #: result in ``reward``/``observation``/``done`` with :meth:`outputs`. None: not used.
    batched_outputs: Optional[Callable[[Tensor, Tensor], Any]] = None

    def outputs(self):
        """The value of :meth:`batched_outputs` for the world's current state, computed at most once per state
        (by the step itself, in the same compiled graph, when the world compiles its physics)."""
        if self._outputs is None:
            raise RuntimeError(f"{type(self).__name__}.outputs(): the scenario does not define batched_outputs")
        return self._outputs()

    # -- optional: every agent at once (the stacked step, vmas_ros.envs.stacked) ------
    # A swarm's environment step given stacked actions returns stacked results; these hooks let a
    # scenario compute them without a call per agent. Each returns None (the default) to be asked
    # agent by agent instead, or fresh tensors it never writes to again, with the agents (in order)
    # as the first dimension, holding exactly what the per-agent methods return.

    def stacked_observations(self) -> Optional[Tensor]:
        """Every agent's observation ``[n_agents, batch, obs_size]`` (tensor observations of one shape)."""
        return None

    def stacked_rewards(self) -> Optional[Tensor]:
        """Every agent's reward ``[n_agents, batch]``; called instead of ``reward``, before the observations."""
        return None

    def stacked_infos(self) -> Optional[dict]:
        """Every agent's info, one dict of ``[n_agents, batch, ...]`` tensors."""
        return None

    @abc.abstractmethod
    def observation(self, agent):
        """Observation of ``agent`` in every env: a [batch, n] tensor or a dict of them."""

    @abc.abstractmethod
    def reward(self, agent) -> Tensor:
        """Reward of ``agent`` in every env, shape [batch]."""

    def done(self) -> Tensor:
        """Which envs are finished, shape [batch] bool. Default: never."""
        return torch.zeros(self.world.batch_dim, dtype=torch.bool, device=self.world.device)

    def info(self, agent) -> dict:
        """Extra per-agent metrics, each a tensor with the batch dimension first."""
        return {}

    def observation_layout(self, agent) -> Optional[ObservationLayout]:
        """Where ``agent``'s observation holds its own position, velocity and lidar (for observation noise in
        training, ``vmas_ros.envs.randomisation``); None (the default): not described."""
        return None

    def extra_render(self, env_index: int = 0) -> List:
        """Extra geoms (see simulator.rendering) drawn on top of env ``env_index``."""
        return []

    def process_action(self, agent) -> None:
        """Change ``agent.action.u`` before the dynamics model reads it."""

    def pre_step(self) -> None:
        """Runs once before the physics step."""

    def post_step(self) -> None:
        """Runs once after the physics step."""
