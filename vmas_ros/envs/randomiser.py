"""A :class:`~vmas_ros.envs.randomisation.Randomisation` at work in one environment.

The environment calls it at three points, and only when randomisation is on:

- after a reset of some envs (:meth:`Randomiser.draw`): every setting is drawn
  anew for those envs, their command history and lag state are cleared and
  the world gets their mass and drag scales;
- between an action's check and the agents (:meth:`Randomiser.commands`):
  the command each agent executes, ``[A, B, size]``, delayed and lagged;
- on the observations handed out (:meth:`Randomiser.observations`).

Everything is batched over agents and envs: per-agent-and-env settings are
``[A, B]`` tensors, the command history is one ring buffer ``[D + 1, A, B,
size]`` (``D``: the longest delay in steps) read with one gather, and the
settings drawn at resets come for all agents at once from a generator of
its own, seeded from the env's seed; the observation noise's numbers are a
hash of that seed, the noise's step and the element
(:mod:`~vmas_ros.envs.sensor_noise`), computed inside the noise's kernel.
The scenario's random stream is left as it would be without randomisation,
so the same seed gives the same start states with and without it.
"""
from __future__ import annotations

from functools import partial
from typing import Dict, List, Optional, Tuple, Union

import torch
from torch import Tensor

from vmas_ros.envs import sensor_noise
from vmas_ros.envs.randomisation import HALF_UP, SETTINGS, Randomisation
from vmas_ros.simulator.compiling import WorldKernel
from vmas_ros.simulator.tracing import tracing

__all__ = ["Randomiser", "SEED_OFFSET"]

#: the randomisation's generator starts from the env's seed plus this (any fixed number: apart from the seed)
SEED_OFFSET = 7_919


class Randomiser:
    """Applies ``config`` to ``env`` (an :class:`~vmas_ros.envs.environment.Environment`); refuses, naming why,
    a setting the env cannot take (action sizes that differ, an observation without a layout)."""

    def __init__(self, env, config: Randomisation) -> None:
        self.config = config
        self._env = env
        self._dt = float(env.world.dt)
        self._shape = (env.n_agents, env.num_envs)
        self._active = [name for name in SETTINGS if config.active(name)]
        # what runs in a step, decided once (the config is frozen)
        self._latency, self._lag = config.active("command_latency"), config.active("actuator_lag")
        #: whether the observations handed out go through observations()
        self.on_observations = config.acts_on_observations
        self.generator = torch.Generator(device=env.device)
        self.seed(env.seed_given)
        self.params: Dict[str, Tensor] = {name: torch.full(self._shape, SETTINGS[name][1], device=env.device)
                                          for name in self._active}
        scenario_name = type(env.scenario).__module__.rsplit(".", 1)[-1]
        if config.acts_on_commands:
            sizes = sorted({plan[0] for plan in env._action_plans()})
            if len(sizes) != 1:
                raise ValueError(f"command latency and actuator lag need every agent to take one action size; "
                                 f"{scenario_name}'s agents take {sizes}")
            if config.active("actuator_lag") and not env.continuous_actions:
                raise ValueError("actuator_lag needs continuous actions (a lagged discrete choice means nothing)")
        #: the longest delay in steps, the ring buffer of commands given and where the next goes
        self.max_delay = config.latency_steps(config.command_latency[1], self._dt)
        self._history: Optional[Tensor] = None
        self._slot = 0
        self._delay: Optional[Tensor] = None  # [A, B] long
        self._alpha: Optional[Tensor] = None  # [A, B, 1]
        self._executed: Optional[Tensor] = None  # [A, B, size], the lag's state
        self._layout = None
        if config.acts_on_observations:
            self._layout = _one_layout(env, scenario_name, config)
        self._projection: Optional[Tensor] = None  # [4, O] once the width is known (_projection)
        self._perturb = None  # _perturbed with the layout's lidar columns, compiled with the world's physics
        self._pair_sigma: Optional[Tensor] = None  # [A, B, 4] position, position, velocity, velocity std
        self._lidar_sigma: Optional[Tensor] = None  # [A, B, 1] (None: no lidar noise or dropout)
        self._dropout: Optional[Tensor] = None  # [A, B, 1]
        self._reads: Optional[Tensor] = None  # [D + 1, A * B] history rows per slot (_read_rows)
        self._agent_rows: Optional[Tensor] = None
        if config.acts_on_dynamics:
            rows = {id(entity): row for row, entity in enumerate(env.world.entities)}
            self._agent_rows = torch.tensor([rows[id(agent)] for agent in env.agents], device=env.device)

    def seed(self, seed: int) -> None:
        """Start the draws afresh from the env's ``seed`` (a stream of their own, apart from the scenario's)."""
        self.generator.manual_seed(SEED_OFFSET + int(seed))
        device = self.generator.device
        # the observation noise's numbers: a hash of (seed, step of the noise, element), see sensor_noise
        self._seed_key = sensor_noise.hash32(torch.tensor(_as_int32(SEED_OFFSET + int(seed)), dtype=torch.int32,
                                                          device=device))
        self._step = torch.zeros((), dtype=torch.int32, device=device)

    # ------------------------------------------------------------------- resets
    def draw(self, envs: Optional[Tensor]) -> None:
        """Draw every active setting anew for ``envs`` (a 1-D index tensor; None: all) and clear their state."""
        n_agents, n_envs = self._shape
        columns = slice(None) if envs is None else envs
        count = n_envs if envs is None else int(envs.numel())
        device = self._env.device
        for name in self._active:
            low, high = getattr(self.config, name)
            values = (torch.rand(n_agents, count, device=device, generator=self.generator) * (high - low) + low
                      if high > low else low)
            self.params[name][:, columns] = values
        if self._latency:
            self._delay = torch.floor(self.params["command_latency"] / self._dt + HALF_UP).long().clamp_(0, self.max_delay)
            self._reads = None
        if self._lag:
            tau = self.params["actuator_lag"]  # 0: no lag, the command is executed as it comes (alpha 1)
            alpha = 1 - torch.exp(-self._dt / tau.clamp_min(torch.finfo(tau.dtype).tiny))
            self._alpha = torch.where(tau > 0, alpha, torch.ones_like(alpha)).unsqueeze(-1)
        if self._history is not None:
            self._history.view(self.max_delay + 1, n_agents, n_envs, -1)[:, :, columns] = 0
        if self._executed is not None:
            self._executed[:, columns] = 0
        if self.config.acts_on_dynamics:
            self._scale_world()
        if self.config.acts_on_observations:
            self._observation_scales()

    def _observation_scales(self) -> None:
        """The noise's standard deviations (and the dropout) per agent and env, in the forms _perturbed takes."""
        params, zeros = self.params, torch.zeros(self._shape, device=self._env.device)
        position, velocity = params.get("position_noise", zeros), params.get("velocity_noise", zeros)
        self._pair_sigma = torch.stack([position, position, velocity, velocity], dim=-1)
        if self.config.active("lidar_noise", "lidar_dropout"):
            self._lidar_sigma = params.get("lidar_noise", zeros).unsqueeze(-1)
            self._dropout = params.get("lidar_dropout", zeros).unsqueeze(-1)

    def _scale_world(self) -> None:
        world = self._env.world
        full = {}
        for name in ("mass_scale", "drag_scale"):
            values = torch.ones(len(world.entities), world.batch_dim, device=world.device)
            if name in self.params:
                values[self._agent_rows] = self.params[name]
            full[name] = values
        world.scale_dynamics(full["mass_scale"], full["drag_scale"])

    # ----------------------------------------------------------------- commands
    def commands(self, given: Tensor) -> Tensor:
        """What each agent executes this step, ``[A, B, size]``, from the commands ``given`` now."""
        executed = given
        if self._latency:
            if self._history is None:
                self._history = torch.zeros((self.max_delay + 1) * given.shape[0] * given.shape[1], given.shape[2],
                                            dtype=given.dtype, device=given.device)
                self._reads = None
            if self._reads is None:
                self._reads = _read_rows(self._delay, self.max_delay + 1)
            rows = given.shape[0] * given.shape[1]
            self._history[self._slot * rows:(self._slot + 1) * rows] = given.reshape(rows, -1)
            executed = self._history.index_select(0, self._reads[self._slot]).view(given.shape)
            self._slot = (self._slot + 1) % (self.max_delay + 1)
        if self._lag:
            if self._executed is None:
                self._executed = torch.zeros_like(given)
            self._executed = torch.lerp(self._executed, executed, self._alpha)
            executed = self._executed
        return executed

    # ------------------------------------------------------------- observations
    def observations(self, obs: Union[Tensor, Tuple[Tensor, ...]]):
        """Every agent's observation ``[A, B, O]`` as a robot's sensors would give it (a new tensor); given
        a tuple of ``[B, O]``, one per agent, a tuple of new ones."""
        layout = self._layout
        shape = obs.shape if isinstance(obs, Tensor) else (len(obs), *obs[0].shape)
        if self._projection is None or self._projection.shape[1] != shape[2]:
            if layout.width_needed() > shape[2]:
                raise ValueError(f"the observation layout needs {layout.width_needed()} columns, but the "
                                 f"observations have {shape[2]}")
            self._projection = _projection(layout, shape[2], obs if isinstance(obs, Tensor) else obs[0])
            self._perturb = WorldKernel(self._env.world, partial(_perturbed, lidar=None if layout.lidar is None else (
                layout.lidar.start, layout.lidar.count, float(layout.lidar.max_value), float(layout.lidar.miss))))
        noisy = self._perturb(obs, self._seed_key, self._step, self._pair_sigma, self._projection, self._lidar_sigma,
                              self._dropout)
        self._step.add_(1)
        return noisy

    def observation_list(self, obs: List[Tensor]) -> List[Tensor]:
        """:meth:`observations` for one ``[B, O]`` tensor per agent (stacked and split inside the kernel,
        where a compiled one reads and writes them in place of two more passes over the observations)."""
        return list(self.observations(tuple(obs)))


def _as_int32(value: int) -> int:
    """The int32 whose bits are ``value``'s low 32."""
    value &= 0xFFFFFFFF
    return value - (1 << 32) if value >= 1 << 31 else value


def _read_rows(delay: Tensor, period: int) -> Tensor:
    """``[period, A * B]``: per ring slot, the rows of the flat ``[period * A * B, size]`` history each agent and env
    executes when the newest command went into that slot (its command ``delay`` steps back)."""
    n_agents, n_envs = delay.shape
    slots = torch.arange(period, device=delay.device).view(period, 1, 1)
    cell = torch.arange(n_agents * n_envs, device=delay.device).view(1, n_agents, n_envs)
    return (((slots - delay.unsqueeze(0)) % period) * (n_agents * n_envs) + cell).flatten(1)


def _projection(layout, width: int, like: Tensor) -> Tensor:
    """``[4, width]``: a (position x, y, velocity x, y) error times it lands on every column that moves with it."""
    matrix = torch.zeros(4, width, dtype=like.dtype, device=like.device)
    for offset, pairs in ((0, layout.position), (2, layout.velocity)):
        for column, sign in pairs:
            matrix[offset, column] = float(sign)
            matrix[offset + 1, column + 1] = float(sign)
    return matrix


def _perturbed(obs, seed_key: Tensor, step: Tensor, pair_sigma: Tensor, projection: Tensor,
               lidar_sigma: Optional[Tensor], dropout: Optional[Tensor], lidar):
    """``obs`` ``[A, B, O]`` as a robot's sensors would give it, with the random numbers of noise ``step``
    (0-d int32) of the stream ``seed_key`` (see :mod:`~vmas_ros.envs.sensor_noise`); ``obs`` given as a
    tuple of each agent's ``[B, O]`` gives a tuple back.

    Four normal errors per agent and env, times ``pair_sigma`` ``[A, B, 4]``, are the position and velocity
    errors, which ``projection`` ``[4, O]`` puts on every column that moves with them. Per lidar ray: a normal
    error times ``lidar_sigma`` ``[A, B, 1]``, and a dropout with probability ``dropout`` ``[A, B, 1]``.
    A ray that saw nothing still sees nothing; the others stay in the sensor's range. A pure function
    of its arguments: it compiles with the world's physics.
    """
    if not isinstance(obs, Tensor):
        return _perturbed(torch.stack(obs), seed_key, step, pair_sigma, projection, lidar_sigma, dropout,
                          lidar).unbind(0)
    n_agents, n_envs, _ = obs.shape
    rays = 0 if lidar is None else lidar[1]
    numbers = sensor_noise.hashes(sensor_noise.stream_key(seed_key, step), (n_agents, n_envs, 4 + rays))
    errors = sensor_noise.normals(numbers[..., :4], obs.dtype) * pair_sigma
    if tracing():  # four broadcast products fuse with the rest
        noisy = obs + (errors.unsqueeze(-1) * projection).sum(dim=-2)
    else:  # one matmul is the cheaper eager call
        noisy = torch.addmm(obs.reshape(-1, obs.shape[-1]), errors.reshape(-1, 4), projection).view(obs.shape)
    if lidar_sigma is None:
        return noisy
    start, count, max_value, miss = lidar
    per_ray = numbers[..., 4:]
    kept = sensor_noise.uniforms(per_ray, obs.dtype) > dropout
    ray_errors = sensor_noise.normals(per_ray, obs.dtype)
    readings = obs[..., start:start + count]
    seen = (readings + lidar_sigma * ray_errors).clamp(0.0, max_value)
    readings = torch.where((readings != miss) & kept, seen, torch.full_like(readings, miss))
    return torch.cat([noisy[..., :start], readings, noisy[..., start + count:]], dim=-1)


def _one_layout(env, scenario_name: str, config: Randomisation):
    """The agents' shared observation layout; a ValueError says why there is none to use."""
    layouts = [env.scenario.observation_layout(agent) for agent in env.agents]
    if any(layout is None for layout in layouts):
        raise ValueError(f"observation noise needs to know where {scenario_name}'s observations hold the agents' "
                         f"positions, velocities and lidar: its scenario defines no observation_layout")
    if any(layout != layouts[0] for layout in layouts):
        raise ValueError(f"observation noise needs every agent of {scenario_name} to observe in one layout")
    if config.active("lidar_noise", "lidar_dropout") and layouts[0].lidar is None:
        raise ValueError(f"lidar noise and dropout: {scenario_name}'s observations (with these kwargs) hold no lidar")
    return layouts[0]
