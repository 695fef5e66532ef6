"""diff_drive (debug): a differential-drive robot beside an omnidirectional one.

Description
    A playground for the ``DiffDrive`` dynamics (the unicycle model of ROS
    ``cmd_vel`` robots). Agent ``diff_drive_0`` is commanded with (forward
    speed, turn rate), integrated with RK4 over each step; every further agent
    ``holo_rot_<i>`` is holonomic with its own heading, commanded with a
    world-frame force and a torque (scaled by 0.001). All are colliding discs
    of the default radius 0.05, in a world with 10 substeps. There is no task:
    the reward is always zero.
Observation (per agent, in this order)
    own position (2), own velocity (2).
Reward
    Zero, shape [B].
Starting state
    Agents uniform in [-1, 1]^2 at least 0.1 apart, at rest, heading 0.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (2; the first is the differential-drive robot).

Heuristic
    As there is no reward, the shipped ``HeuristicPolicy`` drives every agent
    home to the origin (the centre of the spawn square) and is measured on
    the distance to it.

This module also holds the pieces the sibling debug scenarios
``kinematic_bicycle`` and ``drone`` share with it: the spawning, zero-reward,
position-and-velocity base scenario and the go-home controllers.
"""
from __future__ import annotations

import math
from typing import Sequence, Tuple

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_int, continuous_heuristic_kwargs, read_kwargs
from vmas_ros.simulator.core import Agent, World
from vmas_ros.simulator.dynamics.diff_drive import DiffDrive
from vmas_ros.simulator.dynamics.holonomic_with_rot import HolonomicWithRotation
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import ScenarioUtils

DEFAULTS = {"n_agents": 2}
SUBSTEPS = 10
#: u_multiplier of the holonomic agents: (fx, fy, torque); the torque is scaled down
HOLO_MULTIPLIER = [1, 1, 0.001]
SPAWN_HALF_WIDTH = 1.0
SPAWN_MIN_DIST = 0.1



class SpawnScenario(BaseScenario):
    """Base of the dynamics debug scenarios: random spawn, zero reward, (pos, vel) observations.

    Subclasses build the world in ``make_world``; resets accept None, an int
    or a 1-D tensor of env indices (or a mask).
    """

    supports_batched_reset = True
    fresh_observations = True

    def reset_world_at(self, env_index=None) -> None:
        # world.reset has zeroed every state (and the dynamics' memory) in these envs
        ScenarioUtils.spawn_entities_randomly(
            self.world.agents, self.world, env_index,
            min_dist_between_entities=SPAWN_MIN_DIST,
            x_bounds=(-SPAWN_HALF_WIDTH, SPAWN_HALF_WIDTH),
            y_bounds=(-SPAWN_HALF_WIDTH, SPAWN_HALF_WIDTH),
        )

    def reward(self, agent: Agent) -> Tensor:
        return torch.zeros(self.world.batch_dim, device=self.world.device)

    def observation(self, agent: Agent) -> Tensor:
        """[B, 4]: position, velocity."""
        return torch.cat([agent.state.pos, agent.state.vel], dim=-1)

    def extra_render(self, env_index: int = 0) -> list:
        return [ScenarioUtils.plot_entity_rotation(agent, env_index, length=0.1) for agent in self.world.agents]


class Scenario(SpawnScenario):
    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        check_int("diff_drive", "n_agents", config["n_agents"])
        self.n_agents = config["n_agents"]
        self.plot_grid = True

        world = World(batch_dim, device, substeps=SUBSTEPS)
        world.add_agent(Agent(
            name="diff_drive_0", collide=True, render_action=True, u_range=[1, 1], u_multiplier=[1, 1],
            dynamics=DiffDrive(world, integration="rk4"),
        ))
        for i in range(1, self.n_agents):
            world.add_agent(Agent(
                name=f"holo_rot_{i}", collide=True, render_action=True, u_range=[1, 1, 1],
                u_multiplier=HOLO_MULTIPLIER, dynamics=HolonomicWithRotation(),
            ))
        return world


# ------------------------------------------------------------ evaluation
#: What ``vmas-ros evaluate`` scores this reward-less world on, per step (see ``task_score``).
TASK_SCORE = "minus the mean distance to the origin [m]"


def task_score(env, observations) -> Tensor:
    """[B]: minus the agents' mean distance to the origin, the heuristic's stand-in goal.

    The reward is always zero, so ``vmas-ros evaluate`` sums this per step instead to tell
    a heuristic from random play. ``observations`` (one [B, 4] per agent) are not needed.
    """
    return -torch.stack([agent.state.pos.norm(dim=-1) for agent in env.agents]).mean(dim=0)


# ----------------------------------------------------------------- heuristics
def wrap_angle(angle: Tensor) -> Tensor:
    """``angle`` mapped to [-pi, pi)."""
    return torch.remainder(angle + math.pi, 2 * math.pi) - math.pi


def holonomic_home(observation: Tensor, u_range: Sequence[float], gain: float = 2.0, damping: float = 2.0) -> Tensor:
    """(fx, fy, torque) of a PD pull to the origin, no torque: [B, 3] for a (pos, vel, ...) observation."""
    pos, vel = observation[:, 0:2], observation[:, 2:4]
    force = -gain * pos - damping * vel
    limit = torch.tensor([float(u) for u in u_range[:2]], device=observation.device)
    force = torch.maximum(torch.minimum(force, limit), -limit)
    return torch.cat([force, torch.zeros_like(force[:, :1])], dim=-1)


def steer_home(
    observation: Tensor, max_speed: float, max_turn: float,
    speed_gain: float = 1.0, turn_gain: float = 2.0, creep: float = 0.05, brake: float = 0.8,
) -> Tuple[Tensor, Tensor]:
    """(speed, turn) [B] each, driving a non-holonomic vehicle to the origin.

    The heading is not observed, but a vehicle moving forwards has its
    velocity along it (a bicycle's is off by the small slip angle), so the
    turn command steers the velocity towards the origin. The speed never drops
    below ``creep``: standing still would lose the heading. It slows down when
    facing away (to turn tightly), by at most ``1 - brake`` of its speed per step.
    """
    pos, vel = observation[:, 0:2], observation[:, 2:4]
    bearing = torch.atan2(-pos[:, 1], -pos[:, 0])
    heading = torch.atan2(vel[:, 1], vel[:, 0])
    moving = torch.linalg.vector_norm(vel, dim=-1) > 1e-3
    error = torch.where(moving, wrap_angle(bearing - heading), torch.zeros_like(bearing))
    turn = (turn_gain * error).clamp(-max_turn, max_turn)
    distance = torch.linalg.vector_norm(pos, dim=-1)
    speed = speed_gain * distance * torch.cos(error).clamp_min(0.0)
    # brake gradually: a sudden stop overshoots into reversing (the engine's drag and substeps do
    # not follow the one-step model exactly), which would flip the velocity-based heading estimate
    speed = torch.maximum(speed, brake * torch.linalg.vector_norm(vel, dim=-1)).clamp(creep, max_speed)
    return speed, turn


class HeuristicPolicy(BaseHeuristicPolicy):
    """Drive home to the origin (there is no reward to chase; see the module docstring).

    Which robot is being controlled is told by the action size, i.e.
    ``len(u_range)``: 2 for the differential-drive robot (speed, turn rate;
    see ``steer_home``), 3 for the holonomic ones (a PD force to the origin,
    no torque). Continuous actions only.
    """

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs("diff_drive", DEFAULTS, scenario_kwargs, continuous_action)
        check_int("diff_drive", "n_agents", config["n_agents"])

    def compute_action(self, observation: Tensor, u_range: Sequence[float]) -> Tensor:
        if len(u_range) == 3:
            return holonomic_home(observation, u_range)
        speed, turn = steer_home(observation, float(u_range[0]), float(u_range[1]))
        return torch.stack([speed, turn], dim=-1)
