"""het_mass: two agents of different, noisy mass share a reward for the fastest one's speed.

Description
    A debug world for heterogeneous teams. Two non-colliding disc agents move
    freely (no walls, world drag 0.25, dt 0.1): ``agent 0`` (green) of mass
    ``green_mass`` and ``agent 1`` (blue) of mass ``blue_mass``, each redrawn
    uniformly within +-``mass_noise`` of its nominal value. Only the x
    component of an action acts (the y component is zeroed), with forces up
    to 1 per axis. Both agents earn the speed of the faster one minus a shared
    energy cost, so the team does best when only the lighter agent pushes.
Observation (per agent, in this order)
    own position (2), own velocity (2).
Reward
    Shared by both agents: ``max_speed`` (the larger of the two agents' speeds)
    plus ``energy_expenditure``, which is -0.17 x the sum over agents of
    ``|u| / (sqrt(2) * f_range)`` (``f_range`` = 1), ``u`` the force after its y
    component was zeroed. ``info`` reports both terms.
Starting state
    Each agent uniform in [-1, 1]^2, at rest.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``green_mass`` (4), ``blue_mass`` (2), ``mass_noise`` (1).
Deviations from VMAS 1.5
    A mass is one number shared by every env of the batch (in VMAS too). VMAS
    redraws both masses, from NumPy's global generator, on every reset,
    including a reset of a single env, so resetting one env changes the
    dynamics of all the others. Here the masses are drawn from torch's
    generator on the world's device, and only when a reset covers every env
    of the batch: a partial reset leaves the other envs as they were. A mass
    range that reaches 0 (``mass_noise >= green_mass`` or ``blue_mass``) raises
    ``ValueError`` instead of producing non-positive masses.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import configure, heuristic_kwargs, selected_rows, uniform_rows
from vmas_ros.simulator.core import Agent, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

NAME = "het_mass"
#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {"green_mass": 4.0, "blue_mass": 2.0, "mass_noise": 1.0}
F_RANGE = 1.0
ENERGY_COEFF = 0.17
SPAWN = 1.0  # agents spawn uniformly in [-SPAWN, SPAWN]^2


def validate(config: dict) -> None:
    """Raise ``ValueError`` for a mass setting that could give a non-positive mass."""
    noise = config["mass_noise"]
    if not (isinstance(noise, (int, float)) and noise >= 0):
        raise ValueError(f"{NAME}: mass_noise must be a number >= 0, got {noise!r}")
    for name in ("green_mass", "blue_mass"):
        mass = config[name]
        if not (isinstance(mass, (int, float)) and mass - noise > 0):
            raise ValueError(f"{NAME}: {name} must be a number > mass_noise ({noise}) so masses stay positive, got {mass!r}")


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.plot_grid = True

        world = World(batch_dim, device)
        self.green_agent = Agent(
            name="agent 0", collide=False, color=Color.GREEN, render_action=True, mass=self.green_mass, f_range=F_RANGE
        )
        self.blue_agent = Agent(name="agent 1", collide=False, render_action=True, f_range=F_RANGE)
        world.add_agent(self.green_agent)
        world.add_agent(self.blue_agent)
        #: multiplies an action to keep only its x component
        self._x_only = torch.tensor([1.0, 0.0], device=world.device)
        self._energy_scale = ENERGY_COEFF / math.sqrt(world.dim_p * F_RANGE**2)
        #: per env [B]: the two reward terms of the last step
        self.max_speed = torch.zeros(batch_dim, device=world.device)
        self.energy_expenditure = self.max_speed.clone()
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        if selected_rows(world.batch_dim, env_index) == world.batch_dim:
            # masses are shared by the whole batch: redraw them only when every env restarts
            nominal = torch.tensor([self.green_mass, self.blue_mass], device=world.device)
            noise = torch.empty(2, device=world.device).uniform_(-self.mass_noise, self.mass_noise)
            self.green_agent.mass, self.blue_agent.mass = (nominal + noise).tolist()
        for agent in world.agents:
            agent.set_pos(uniform_rows(world, env_index, world.dim_p, -SPAWN, SPAWN), batch_index=env_index)

    def process_action(self, agent: Agent) -> None:
        agent.action.u = agent.action.u * self._x_only

    def reward(self, agent: Agent) -> Tensor:
        agents = self.world.agents
        if agent is agents[0]:
            speeds = torch.stack([torch.linalg.vector_norm(a.state.vel, dim=-1) for a in agents], dim=1)
            self.max_speed = speeds.max(dim=1).values
            forces = torch.stack([torch.linalg.vector_norm(a.action.u, dim=-1) for a in agents], dim=1)
            self.energy_expenditure = -(forces * self._energy_scale).sum(dim=1)
        return self.max_speed + self.energy_expenditure

    def observation(self, agent: Agent) -> Tensor:
        return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

    def info(self, agent: Agent) -> dict:
        return {"max_speed": self.max_speed, "energy_expenditure": self.energy_expenditure}


class HeuristicPolicy(BaseHeuristicPolicy):
    """Only the lighter agent pushes, at full force along its direction of travel.

    The observation does not say which agent is which, so the policy lets the
    physics tell: at rest an agent pushes once at full force; a full push
    from rest gives speed ``dt * f / mass``, so the light agent comes out
    faster than ``threshold`` (that speed for the mean of the two nominal
    masses) and keeps pushing, while the heavy one comes out slower, stops
    pushing and coasts to a halt (when it pushes once more). The team earns
    the light agent's top speed (``0.4 f / mass`` with drag 0.25) for a single
    agent's energy.
    """

    #: below this speed an agent counts as at rest and gives its one probing push
    rest_speed = 1e-4

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        if not continuous_action:
            raise ValueError(f"{NAME} HeuristicPolicy needs continuous actions")
        config = heuristic_kwargs(NAME, DEFAULTS, scenario_kwargs)
        validate(config)
        dt = 0.1  # the world's default step
        self.threshold = dt * F_RANGE / ((config["green_mass"] + config["blue_mass"]) / 2)

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        if observation.shape[-1] != 4:
            raise ValueError(f"{NAME} heuristic: expected observation width 4, got {observation.shape[-1]}")
        vx = observation[:, 2]
        speed = torch.linalg.vector_norm(observation[:, 2:4], dim=-1)
        push = (speed < self.rest_speed) | (speed > self.threshold)
        direction = torch.where(vx < 0, -1.0, 1.0)
        force_x = torch.where(push, direction * min(u_range, F_RANGE), 0.0)
        return torch.stack([force_x, torch.zeros_like(force_x)], dim=-1)
