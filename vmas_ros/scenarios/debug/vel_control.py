"""vel_control (debug): three velocity-controlled agents and the energy they spend.

Description
    A playground for the PID ``VelocityController``: actions are desired
    velocities (norm at most 1), turned into forces by a controller with
    ``(gain, intg_ts, derv_ts) = (2, 6, 0.002)`` in the standard form. The
    world has linear friction 0.1, no drag, dt 0.05 and 4 substeps. The
    three non-colliding agents differ in how they can accelerate:

    * ``agent 0`` (green): mass ``green_mass``, force limited to 1.1 per axis;
    * ``agent 1``: no force limit, but its x command is first rate-limited so
      that the desired x velocity is at most 1 (m/s^2) x dt from its current one;
    * ``agent 2``: force limited to 30 per axis.

    Commands are first clipped to the unit disc, and commands shorter than
    0.08 are zeroed (a dead band, as a joystick has). ``landmark 0`` is a
    movable, non-colliding marker left at the origin.
Observation (per agent, in this order)
    own position (2), own velocity (2).
Reward
    Shared: minus 3 x the sum over agents of the norm of the controller's
    force output (before the force limits apply), shape [B]. ``info``
    reports it as ``energy_expenditure`` for every agent.
Starting state
    Every agent at (-1, 0) at rest, controllers cleared; the landmark at the
    origin.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``green_mass`` (1, the mass of agent 0).

VMAS warns at construction that agent 1's controller has no force limit
(its integrator can wind up); that is the point of agent 1, so the warning
is silenced here.
"""
from __future__ import annotations

import math
import warnings
from typing import Dict

import torch
from torch import Tensor

from vmas_ros.scenarios.common import configure, continuous_heuristic_kwargs, for_index, selected_rows
from vmas_ros.simulator.controllers.velocity_controller import VelocityController
from vmas_ros.simulator.core import Agent, Landmark, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color, TorchUtils

DEFAULTS = {"green_mass": 1}
#: PID (gain, integral time, derivative time), standard form
CONTROLLER_PARAMS = (2, 6, 0.002)
LINEAR_FRICTION = 0.1
DT = 0.05
SUBSTEPS = 4
MAX_SPEED_COMMAND = 1.0
#: agent 0's force limit: enough to beat friction and accelerate at 1
GREEN_F_RANGE = LINEAR_FRICTION + 1.0
FAST_F_RANGE = 30.0
#: agent 1: largest change of its x velocity command per second
MAX_X_ACCEL = 1.0
DEAD_BAND = 0.08
ENERGY_COEFF = 3.0
START = (-1.0, 0.0)


def validate(config: dict) -> None:
    mass = config["green_mass"]
    if isinstance(mass, bool) or not isinstance(mass, (int, float)) or not (math.isfinite(mass) and mass > 0):
        raise ValueError(f"vel_control: green_mass must be a finite number > 0, got {mass!r}")


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        configure(self, kwargs, DEFAULTS, validate)
        self.plot_grid = True

        world = World(batch_dim, device, linear_friction=LINEAR_FRICTION, drag=0, dt=DT, substeps=SUBSTEPS)
        limits = (GREEN_F_RANGE, None, FAST_F_RANGE)
        for i, f_range in enumerate(limits):
            extra = {"color": Color.GREEN, "mass": self.green_mass} if i == 0 else {}
            agent = Agent(
                name=f"agent {i}", collide=False, render_action=True, f_range=f_range,
                u_range=MAX_SPEED_COMMAND, **extra,
            )
            with warnings.catch_warnings():  # agent 1 is unlimited on purpose (see the module docstring)
                warnings.simplefilter("ignore")
                agent.controller = VelocityController(agent, world, CONTROLLER_PARAMS, "standard")
            world.add_agent(agent)
        self.rate_limited = world.agents[1]
        self.landmark = Landmark("landmark 0", collide=False, movable=True)
        world.add_landmark(self.landmark)
        #: the shared reward of the last step, [B]
        self.energy_expenditure = torch.zeros(batch_dim, device=device)
        return world

    def reset_world_at(self, env_index=None) -> None:
        # world.reset has put everything at the origin at rest; only the agents move to the start
        rows = selected_rows(self.world.batch_dim, env_index)
        start = torch.tensor(START, device=self.world.device).expand(rows, 2)
        for agent in self.world.agents:
            agent.controller.reset(env_index)
            agent.set_pos(for_index(start.clone(), env_index), batch_index=env_index)

    def process_action(self, agent: Agent) -> None:
        u = TorchUtils.clamp_with_norm(agent.action.u, agent.u_range)
        u = torch.where(torch.linalg.vector_norm(u, dim=1, keepdim=True) < DEAD_BAND, 0.0, u)
        if agent is self.rate_limited:
            vel_x = agent.state.vel[:, :1]
            # written as a clamped acceleration times dt, so it rounds as VMAS does
            accel = ((u[:, :1] - vel_x) / self.world.dt).clamp(-MAX_X_ACCEL, MAX_X_ACCEL)
            u = torch.cat([accel * self.world.dt + vel_x, u[:, 1:]], dim=1)
        agent.action.u = u
        agent.controller.process_force()

    def reward(self, agent: Agent) -> Tensor:
        if agent is self.world.agents[0]:  # shared: computed once per step
            forces = torch.stack([torch.linalg.vector_norm(a.action.u, dim=-1) for a in self.world.agents], dim=1)
            self.energy_expenditure = -forces.sum(-1) * ENERGY_COEFF
        return self.energy_expenditure

    def observation(self, agent: Agent) -> Tensor:
        """[B, 4]: position, velocity."""
        return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

    def info(self, agent: Agent) -> Dict[str, Tensor]:
        return {"energy_expenditure": self.energy_expenditure}


class HeuristicPolicy(BaseHeuristicPolicy):
    """Spend as little energy as possible: stand still, and coast to a stop when moving.

    The reward only charges the controllers' force. An agent at rest with a
    command inside the dead band gets no force at all, so the heuristic
    commands zero velocity at rest; when it is moving it commands its own
    velocity scaled by ``coast`` (slightly slower), so the controller brakes
    gently instead of with the full force a zero command would ask for.
    Continuous actions only.
    """

    coast = 0.9

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        validate(continuous_heuristic_kwargs("vel_control", DEFAULTS, scenario_kwargs, continuous_action))

    def compute_action(self, observation: Tensor, u_range: float) -> Tensor:
        vel = observation[:, 2:4]
        return TorchUtils.clamp_with_norm(self.coast * vel, u_range)
