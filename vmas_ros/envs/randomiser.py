"""A :class:`~vmas_ros.envs.randomisation.Randomisation` at work in one environment.

The environment calls it at three points, and only when randomisation is on:

- after a reset of some envs (:meth:`Randomiser.draw`): every setting is drawn
  anew for those envs, their command history and lag state are cleared and
  the world gets their mass and drag scales;
- between an action's check and the agents (:meth:`Randomiser.commands`):
  the command each agent executes, ``[A, B, size]``, delayed and lagged;
- on the observations handed out (:meth:`Randomiser.observations`).

Everything is batched over agents and envs: per-agent-and-env settings are
``[A, B]`` tensors, the command history is a shift register ``[D + 1, A, B,
size]`` (``D``: the longest delay in steps; row ``k``: the command given
``k`` steps ago) read with one gather, and the settings drawn at resets
come for all agents at once from a generator of its own, seeded from the
env's seed. The observation noise is one pass over the observations'
elements: each column knows which error moves it and by how much
(per-column tables made at each reset), and each element computes that
error's random number itself, a hash of the seed, the noise's step and the
error's index (:mod:`~vmas_ros.envs.sensor_noise`), so the columns that
share a position error get the same one. The commands and the noise are
pure functions, compiled with the world's physics when it compiles.
The scenario's random stream is left as it would be without randomisation,
so the same seed gives the same start states with and without it.
"""
from __future__ import annotations

from functools import partial
from typing import Dict, List, Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.envs import sensor_noise
from vmas_ros.envs.randomisation import HALF_UP, SETTINGS, Randomisation
from vmas_ros.simulator.compiling import WorldKernel

__all__ = ["CommandsRefused", "Randomiser", "SEED_OFFSET"]

#: the randomisation's generator starts from the env's seed plus this (any fixed number: apart from the seed)
SEED_OFFSET = 7_919


class CommandsRefused(Exception):
    """The commands given to :meth:`Randomiser.commands` were out of their bounds: nothing was executed."""


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
        #: whether the commands go through commands() (which can check their bounds in the same pass)
        self.on_commands = config.acts_on_commands
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
        #: the longest delay in steps, and the commands of the last D + 1 steps (row k: k steps ago)
        self.max_delay = config.latency_steps(config.command_latency[1], self._dt)
        self._history: Optional[Tensor] = None
        self._delay: Optional[Tensor] = None  # [A, B] long
        self._read: Optional[Tensor] = None  # [1, A * B * size] long: the delay per element, as gather's index
        self._alpha: Optional[Tensor] = None  # [A, B, 1]
        self._alpha_flat: Optional[Tensor] = None  # [A * B * size]
        self._executed: Optional[Tensor] = None  # [A * B * size], the lag's state
        self._delay_and_lag = WorldKernel(env.world, _delayed_and_lagged)
        self._layout = None
        if config.acts_on_observations:
            self._layout = _one_layout(env, scenario_name, config)
        self._columns: Optional[_NoiseColumns] = None  # once the observations' shape is known
        self._perturb = None  # per_agent -> _perturbed as a WorldKernel (compiled with the world's physics)
        self._column_scale: Optional[Tensor] = None  # [A * B * O] each element's error's standard deviation
        self._dropout: Optional[Tensor] = None  # [A * B * O], -1 off the rays (None: no lidar noise or dropout)
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
            self._read = None
        if self._lag:
            tau = self.params["actuator_lag"]  # 0: no lag, the command is executed as it comes (alpha 1)
            alpha = 1 - torch.exp(-self._dt / tau.clamp_min(torch.finfo(tau.dtype).tiny))
            self._alpha = torch.where(tau > 0, alpha, torch.ones_like(alpha)).unsqueeze(-1)
            self._alpha_flat = None
        if self._history is not None:
            self._history.view(self.max_delay + 1, n_agents, n_envs, -1)[:, :, columns] = 0
        if self._executed is not None:
            self._executed.view(n_agents, n_envs, -1)[:, columns] = 0
        if self.config.acts_on_dynamics:
            self._scale_world()
        if self.config.acts_on_observations:
            self._observation_scales()

    def _observation_scales(self) -> None:
        """Each column's standard deviation per agent and env, and the dropout, in the forms _perturbed takes
        (once the observations' columns are known: the first observations read them)."""
        if self._columns is None:
            return
        params, zeros = self.params, torch.zeros(self._shape, device=self._env.device)
        sigmas = torch.stack([params.get(name, zeros) for name in _NoiseColumns.SIGMAS], dim=-1)  # [A, B, 3]
        self._column_scale = (sigmas.index_select(-1, self._columns.sigma) * self._columns.sign).reshape(-1)
        if self.config.active("lidar_noise", "lidar_dropout"):  # per element; -1 off the lidar's columns
            dropout = params.get("lidar_dropout", zeros).unsqueeze(-1).expand(*self._shape, self._columns.width)
            self._dropout = torch.where(self._columns.lidar, dropout, -1.0).reshape(-1)

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
    def commands(self, given: Tensor, into: Optional[Tensor] = None, bounds: Optional[Tuple[Tensor, Tensor]] = None
                 ) -> Tensor:
        """What each agent executes this step, ``[A, B, size]``, from the commands ``given`` now; with
        ``into`` (a tensor of their shape), also written into it. ``bounds``: each agent's ``(low, high)``
        ``[A, size]``, checked in the same pass (a NaN fails): out of them, :class:`CommandsRefused` is
        raised and nothing changes."""
        if not self.on_commands:
            if into is not None:
                into.copy_(given)
            return given
        if self._latency:
            if self._history is None:
                self._history = given.new_zeros((self.max_delay + 1, given.numel()))
            if self._read is None:
                self._read = self._delay.view(1, *self._shape, 1).expand(1, *given.shape).reshape(1, -1)
        if self._lag:
            if self._executed is None:
                self._executed = given.new_zeros(given.numel())
            if self._alpha_flat is None:
                self._alpha_flat = self._alpha.expand(given.shape).reshape(-1)
        low, high = (None, None) if bounds is None else bounds
        history, lagged, executed, within = self._delay_and_lag(given, self._history, self._read, self._executed,
                                                                self._alpha_flat, into, low, high)
        if within is not None and not bool(within):
            raise CommandsRefused()
        self._history, self._executed = history, lagged
        return executed

    # ------------------------------------------------------------- observations
    def observations(self, obs: Tensor, per_agent: bool = False):
        """Every agent's observation ``[A, B, O]`` as a robot's sensors would give it (a new tensor), or with
        ``per_agent`` a tuple of each agent's ``[B, O]`` (views of one new tensor)."""
        if self._columns is None or self._columns.width != obs.shape[2]:
            self._columns = _NoiseColumns(self._layout, obs.shape, obs.device)
            self._observation_scales()
            self._perturb = {}
        kernel = self._perturb.get(per_agent)
        if kernel is None:
            lidar = self._layout.lidar
            kernel = self._perturb[per_agent] = WorldKernel(self._env.world, partial(
                _perturbed, per_agent=per_agent,
                lidar=None if lidar is None else (float(lidar.max_value), float(lidar.miss))))
        noisy, self._step = kernel(obs, self._seed_key, self._step, self._columns.index, self._column_scale,
                                   self._dropout)
        return noisy

    def observation_list(self, obs: List[Tensor]) -> List[Tensor]:
        """:meth:`observations` for one ``[B, O]`` tensor per agent."""
        return list(self.observations(torch.stack(obs), per_agent=True))


def _as_int32(value: int) -> int:
    """The int32 whose bits are ``value``'s low 32."""
    value &= 0xFFFFFFFF
    return value - (1 << 32) if value >= 1 << 31 else value


def _delayed_and_lagged(given: Tensor, history: Optional[Tensor], read: Optional[Tensor], lagged: Optional[Tensor],
                        alpha: Optional[Tensor], into: Optional[Tensor], low: Optional[Tensor], high: Optional[Tensor]):
    """``(history, lagged, executed, within)`` for the commands ``given`` ``[A, B, size]``, each of their
    elements flat as one run ``[N]`` (the compiled pass vectorises along it): ``given`` shifted into
    ``history`` ``[D + 1, N]`` (row k: given k steps ago; None: no latency) and read ``read`` ``[1, N]`` rows
    back; then lagged, ``lagged`` (the lag's state, None: no lag) moving by ``alpha`` ``[N]`` towards them;
    ``executed`` in the shape of ``given``. ``within`` (0-d bool; None without ``low``): whether every
    command lies in ``[low, high]`` ``[A, size]`` (a NaN does not). ``into`` (unless None) gets ``executed``
    when within, and keeps what it held otherwise: where the step reads its forces, so the write costs no
    pass of its own. New tensors otherwise: it compiles with the world's physics."""
    within = None
    if low is not None:  # the extremes over the batch against the bounds (NaN fails both comparisons)
        smallest, largest = torch.aminmax(given, dim=1)
        within = ((smallest >= low) & (largest <= high)).all()
    executed = given.reshape(-1)
    if history is not None:
        history = torch.cat([executed.unsqueeze(0), history[:-1]])
        executed = history.gather(0, read).squeeze(0)
    if lagged is not None:
        lagged = executed = torch.lerp(lagged, executed, alpha)
    executed = executed.view(given.shape)
    if into is not None:
        into.copy_(executed if within is None else torch.where(within, executed, into))
    return history, lagged, executed, within


class _NoiseColumns:
    """Per observation column, which error moves it, in tables the noise's one pass reads.

    Each agent and env has ``4 + rays`` errors, numbered as the noise's random
    numbers: the position's x and y, the velocity's x and y, then one per
    lidar ray. ``index`` ``[A * B * O]`` int32, per element of the
    observations (flat: the noise's pass vectorises along one run): the
    number of the error that moves it (``(agent * B + env) * (4 + rays)``
    plus the column's error; a column nothing moves reads error 0 with a
    scale of 0). ``sigma`` ``[O]``: which of :attr:`SIGMAS` scales the
    column's error, and ``sign`` ``[O]`` its sign (0: unmoved); ``lidar``
    ``[O]`` bool: the lidar's rays.
    """

    SIGMAS = ("position_noise", "velocity_noise", "lidar_noise")

    def __init__(self, layout, shape, device) -> None:
        n_agents, n_envs, self.width = shape
        if layout.width_needed() > self.width:
            raise ValueError(f"the observation layout needs {layout.width_needed()} columns, but the "
                             f"observations have {self.width}")
        error, sigma, sign, lidar = [0] * self.width, [0] * self.width, [0.0] * self.width, [False] * self.width
        owner = {}
        for first_error, name, pairs in ((0, "position", layout.position), (2, "velocity", layout.velocity)):
            for column, pair_sign in pairs:
                for axis in (0, 1):
                    if column + axis in owner and owner[column + axis] != name:
                        raise ValueError(f"observation column {column + axis} moves with both the "
                                         f"{owner[column + axis]} and the {name}: a layout gives each column one")
                    owner[column + axis] = name
                    error[column + axis], sigma[column + axis] = first_error + axis, first_error // 2
                    sign[column + axis] = float(pair_sign)
        rays = 0
        if layout.lidar is not None:
            rays = layout.lidar.count
            for ray in range(rays):
                column = layout.lidar.start + ray
                error[column], sigma[column], sign[column], lidar[column] = 4 + ray, 2, 1.0, True
        cells = torch.arange(n_agents * n_envs, dtype=torch.int32, device=device).view(n_agents, n_envs, 1)
        self.index = (cells * (4 + rays) + torch.tensor(error, dtype=torch.int32, device=device)).reshape(-1)
        self.sigma = torch.tensor(sigma, device=device)
        self.sign = torch.tensor(sign, device=device)
        self.lidar = torch.tensor(lidar, device=device)


def _perturbed(obs: Tensor, seed_key: Tensor, step: Tensor, index: Tensor, scale: Tensor, dropout: Optional[Tensor],
               lidar, per_agent: bool):
    """``(noisy, next step)``: the observations ``obs`` ``[A, B, O]`` as a robot's sensors would give them
    (``per_agent``: as a tuple of each agent's ``[B, O]``), with the random numbers of noise ``step`` (0-d
    int32) of the stream ``seed_key`` (see :mod:`~vmas_ros.envs.sensor_noise`). The other arguments hold
    one number per element of ``obs``, flat (``[A * B * O]``: the compiled pass vectorises along one run).

    Each element moves by a normal error times ``scale`` (its column's standard deviation and sign; 0:
    unmoved), the error numbered ``index`` (see :class:`_NoiseColumns`), so every column of one error moves
    by the same amount. Where ``dropout`` is at least 0 (the lidar's rays, with ``lidar`` = ``(max_value,
    miss)``; None: the rays stay as they are), the same number's high byte drops the ray with that
    probability; a ray that saw nothing still sees nothing, the others stay in the sensor's range. One pass
    over the elements, a pure function of its arguments: it compiles with the world's physics.
    """
    flat = obs.reshape(-1)
    numbers = sensor_noise.hash32(index + sensor_noise.stream_key(seed_key, step))
    noisy = flat + sensor_noise.normals(numbers, obs.dtype) * scale
    if dropout is not None:
        max_value, miss = lidar
        kept = (flat != miss) & (sensor_noise.uniforms(numbers, obs.dtype) > dropout)
        readings = torch.where(kept, noisy.clamp(0.0, max_value), torch.full_like(flat, miss))
        noisy = torch.where(dropout >= 0, readings, noisy)
    noisy = noisy.view(obs.shape)
    return (noisy.unbind(0) if per_agent else noisy), step + 1


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
