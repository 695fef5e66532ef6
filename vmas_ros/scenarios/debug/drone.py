"""drone (debug): quadrotors commanded by body torques, kept aloft by a fixed thrust.

Description
    A playground for the ``Drone`` dynamics. ``n_agents`` colliding discs
    ``drone_<i>`` (default radius 0.05, world with 10 substeps) each carry a
    12-state quadrotor model. The action is only the three body torques
    (x, y, z), each in +-1e-5 N m; the scenario prepends a thrust of
    ``mass * g`` (to which the dynamics add the hover thrust ``mass * g``
    again, as in VMAS). Tilting the drone (roll, pitch) moves it in the plane;
    the torque about z turns it. There is no task: the reward is zero, and an
    env ends when some drone tilts too far.

    As the ``Drone`` docstring explains, the planar velocity the engine (and
    so the observation) sees is the model's velocity change per step over dt,
    i.e. about its acceleration ``2 g`` x the tilt: with zero yaw, ``vel_x``
    follows the pitch and ``-vel_y`` the roll.
Observation (per agent, in this order)
    own position (2), own velocity (2).
Reward
    Zero, shape [B].
Starting state
    Agents uniform in [-1, 1]^2 at least 0.1 apart, at rest, heading 0; every
    drone level with zero body rates.
Episode termination
    When the roll or pitch of any drone exceeds 30 degrees.
Kwargs
    ``n_agents`` (2).

Heuristic
    The shipped ``HeuristicPolicy`` keeps the drone level (and so keeps the
    episode alive); it is stateful, see its docstring.
"""
from __future__ import annotations

from typing import Dict

import torch
from torch import Tensor

from vmas_ros.scenarios.common import check_int, continuous_heuristic_kwargs, read_kwargs
from vmas_ros.scenarios.debug.diff_drive import SUBSTEPS, SpawnScenario
from vmas_ros.simulator.core import Agent, World
from vmas_ros.simulator.dynamics.drone import Drone
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy

DEFAULTS = {"n_agents": 2}
MAX_TORQUE = 0.00001
#: hover thrust per unit mass [m/s^2] (the dynamics' ``g``)
GRAVITY = 9.81
#: default pitch/roll inertia of ``Drone``, used by the heuristic to size torques
INERTIA_XY = 8.1e-3


class Scenario(SpawnScenario):
    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        check_int("drone", "n_agents", config["n_agents"])
        self.n_agents = config["n_agents"]
        self.plot_grid = True

        world = World(batch_dim, device, substeps=SUBSTEPS)
        for i in range(self.n_agents):
            world.add_agent(Agent(
                name=f"drone_{i}", collide=True, render_action=True,
                u_range=[MAX_TORQUE] * 3, u_multiplier=[1, 1, 1],
                # only the torques are actions; process_action adds the thrust the dynamics need
                action_size=3,
                dynamics=Drone(world, integration="rk4"),
            ))
        return world

    def process_action(self, agent: Agent) -> None:
        torque = agent.action.u
        thrust = torch.full((torque.shape[0], 1), agent.mass * agent.dynamics.g, device=torque.device)
        agent.action.u = torch.cat([thrust, torque], dim=-1)

    def done(self) -> Tensor:
        crashed = torch.stack([agent.dynamics.needs_reset() for agent in self.world.agents], dim=-1)
        return crashed.any(dim=-1)


#: What ``vmas-ros evaluate`` scores this reward-less world on, per step (see ``task_score``).
TASK_SCORE = "minus the drones' mean tilt [deg]"


def task_score(env, observations) -> Tensor:
    """[B]: minus the drones' mean tilt (the norm of roll and pitch), in degrees.

    The reward is always zero, so ``vmas-ros evaluate`` sums this per step instead;
    staying level is the heuristic's goal (and what keeps an episode alive).
    """
    tilts = [agent.dynamics.drone_state[:, :2].norm(dim=-1) for agent in env.agents]
    return -torch.rad2deg(torch.stack(tilts).mean(dim=0))


class HeuristicPolicy(BaseHeuristicPolicy):
    """Keep the drone level: drive roll and pitch to zero, no yaw torque.

    The attitude is not observed, but the velocity is about ``2 g`` x the
    tilt (see the module docstring): ``(roll, pitch) ~ (-vel_y, vel_x) /
    (2 g)``. The tilt rate is the change of that estimate since the same
    agent's previous call, so this policy is *stateful*. Like every
    heuristic here it may serve all agents, called once per agent per step
    in agent order (as ``vmas-ros evaluate``, ``sim_node`` and VMAS's
    ``run_heuristic`` call it): it keeps one memory per call slot, the call
    count modulo ``n_agents``. Call ``reset()`` when the envs are reset; a
    batch of a different size also starts afresh. Without a yaw torque the
    heading stays 0, which the estimate assumes.

    The torques are tiny (``u_range`` / inertia ~ 1e-3 rad/s^2), so the
    controller is built for saturation: it asks for the tilt rate from which
    braking at ``braking`` x the largest angular acceleration just reaches
    level, ``-sign(tilt) sqrt(2 a |tilt|)``, and tracks it with a
    proportional torque (``rate_gain``), clipped to ``u_range``.
    """

    braking = 0.2  # fraction of the largest angular acceleration planned for braking
    rate_gain = 1.0  # [1/s]
    dt = 0.1  # the world's default dt, which the scenario keeps

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        self.n_agents = continuous_heuristic_kwargs("drone", DEFAULTS, scenario_kwargs, continuous_action)["n_agents"]
        check_int("drone", "n_agents", self.n_agents)
        self._last_tilt: Dict[int, Tensor] = {}  # call slot (agent) -> its last tilt estimate [B, 2]
        self._calls = 0

    def reset(self) -> None:
        """Forget the remembered observations (the next call of each agent estimates zero tilt rate)."""
        self._last_tilt.clear()
        self._calls = 0

    def compute_action(self, observation: Tensor, u_range) -> Tensor:
        slot, self._calls = self._calls % self.n_agents, self._calls + 1
        vel = observation[:, 2:4]
        tilt = torch.stack([-vel[:, 1], vel[:, 0]], dim=-1) / (2 * GRAVITY)  # (roll, pitch)
        last = self._last_tilt.get(slot)
        if last is None or last.shape != tilt.shape or last.device != tilt.device:
            last = tilt
        rate = (tilt - last) / self.dt
        self._last_tilt[slot] = tilt
        limit = torch.tensor([float(u) for u in u_range[:2]], device=observation.device)
        max_accel = self.braking * limit / INERTIA_XY
        wanted_rate = -torch.sign(tilt) * torch.sqrt(2 * max_accel * tilt.abs())
        torque = INERTIA_XY * self.rate_gain * (wanted_rate - rate)
        torque = torch.maximum(torch.minimum(torque, limit), -limit)
        return torch.cat([torque, torch.zeros_like(torque[:, :1])], dim=-1)
