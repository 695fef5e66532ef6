"""wheel: a team spins a heavy line about its centre at a set angular speed.

Description
    A rigid line of ``line_length`` and ``line_mass`` is pinned at the origin:
    it can rotate but not translate (paper, "Multi-robot scenarios"). ``n_agents``
    discs (radius 0.03, force x0.6) push it by contact. The team must bring the
    line's angular speed to ``desired_velocity`` and hold it there; the default
    line is too heavy for one agent, and since only the speed counts (not the
    direction), agents can also brake a line that spins too fast. A small
    non-colliding disc marks the pivot.
Observation (per agent, in this order)
    own position (2), own velocity (2), the line's centre relative to the agent
    (2), each end of the line relative to the agent (2 + 2; the first end lies
    at angle ``rot`` from the centre, the second opposite it), the line's angle
    modulo pi (1), the line's angular speed ``|w|`` (1) and the speed error
    ``||w| - desired_velocity|`` (1): 13 values.
Reward
    Shared by all agents: minus the speed error ``||w| - desired_velocity|``,
    shape [B] (VMAS 1.5 returns it as [B, 1]).
Starting state
    Agents uniform in [-1, 1]^2, at rest; the line at the origin, at rest, at
    an angle uniform in [-pi/2, pi/2].
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``n_agents`` (4), ``line_length`` (2), ``line_mass`` (30),
    ``desired_velocity`` (0.05, rad/s).
"""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios.common import continuous_heuristic_kwargs, read_kwargs
from vmas_ros.scenarios.common import uniform_rows as uniform_for
from vmas_ros.simulator.core import Agent, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import DRAG, LINE_MIN_DIST, Color

AGENT_RADIUS = 0.03
AGENT_U_MULTIPLIER = 0.6
PIVOT_RADIUS = 0.02
DT = 0.1
#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {"n_agents": 4, "line_length": 2.0, "line_mass": 30.0, "desired_velocity": 0.05}


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    if isinstance(config["n_agents"], bool) or not isinstance(config["n_agents"], int) or config["n_agents"] < 1:
        raise ValueError(f"wheel: n_agents must be an int >= 1, got {config['n_agents']!r}")
    for name in ("line_length", "line_mass"):
        if not (isinstance(config[name], (int, float)) and config[name] > 0):
            raise ValueError(f"wheel: {name} must be a number > 0, got {config[name]!r}")
    speed = config["desired_velocity"]
    if not (isinstance(speed, (int, float)) and speed >= 0):
        raise ValueError(f"wheel: desired_velocity must be a number >= 0 (an angular speed), got {speed!r}")


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        validate(config)
        self.n_agents = config["n_agents"]
        self.line_length = float(config["line_length"])
        self.line_mass = float(config["line_mass"])
        self.desired_velocity = float(config["desired_velocity"])

        world = World(batch_dim, device, dt=DT)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), u_multiplier=AGENT_U_MULTIPLIER))
        # not movable: contacts can turn the line but never shift its centre off the origin
        self.line = Landmark(
            name="line", shape=Line(length=self.line_length), collide=True, rotatable=True,
            mass=self.line_mass, color=Color.BLACK,
        )
        world.add_landmark(self.line)
        world.add_landmark(Landmark(name="center", shape=Sphere(radius=PIVOT_RADIUS), collide=False, color=Color.BLACK))
        self._reward: torch.Tensor | None = None
        return world

    def reset_world_at(self, env_index=None) -> None:
        # world.reset has already zeroed every state in these envs (the line's centre stays at the origin)
        for agent in self.world.agents:
            agent.set_pos(uniform_for(self.world, env_index, 2, -1.0, 1.0), batch_index=env_index)
        self.line.set_rot(uniform_for(self.world, env_index, 1, -math.pi / 2, math.pi / 2), batch_index=env_index)

    def speed_error(self) -> torch.Tensor:
        """``||w| - desired_velocity|`` per env, [B, 1]."""
        return (self.line.state.ang_vel.abs() - self.desired_velocity).abs()

    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:  # one shared reward: compute it once per step
            self._reward = -self.speed_error()[:, 0]
        return self._reward

    def observation(self, agent: Agent) -> torch.Tensor:
        rot = self.line.state.rot
        half = self.line_length / 2
        # the ends relative to the pivot (the line never leaves the origin)
        end = torch.cat([half * torch.cos(rot), half * torch.sin(rot)], dim=1)
        pos = agent.state.pos
        return torch.cat([
            pos,
            agent.state.vel,
            self.line.state.pos - pos,
            end - pos,
            -end - pos,
            rot % math.pi,
            self.line.state.ang_vel.abs(),
            self.speed_error(),
        ], dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Every agent pushes the line counter-clockwise, with a force set by the speed error.

    The line splits the plane into two half-planes; an agent in either of them
    is behind exactly one half of the line for counter-clockwise motion, so
    moving counter-clockwise about the pivot takes it there without crossing
    the line. Working in polar coordinates about the pivot, the agent:

    * holds its distance from the pivot within ``[r_min, r_max]`` x half the
      line (a spring on the radius plus damping of its radial speed), so it
      keeps leverage and stays on the line;
    * pushes along its counter-clockwise tangent with a proportional
      controller on the angular speed: a feed-forward (its share of the torque
      that balances the line's drag at the desired speed, plus the force that
      carries itself along at the rim speed) plus its share of a torque that
      would remove ``correction`` of the speed error in one step (scaled by the
      line's inertia, so light and heavy lines alike are stable);
    * damps its tangential speed relative to the rim, slowed to the closing
      speed while it is still catching up with the line: soft contacts would
      otherwise make agent and line bounce.

    Pushes stay in [rim-keeping minimum, u_range]: agents never pull, the
    line's drag brakes it when it is too fast. All agents push the same way,
    so the line turns counter-clockwise and the observed ``|w|`` is its signed
    speed; a line spinning the other way is first slowed by those pushes.
    Needs the scenario's kwargs (``n_agents``, ``line_length``, ``line_mass``,
    ``desired_velocity``); continuous actions only.
    """

    correction = 0.3  # fraction of the speed error the pushes aim to remove in one step
    contact_damping = 5.0
    approach_gain, approach_speed = 2.0, 0.3
    r_min, r_max = 0.5, 0.9
    radial_gain, radial_damping = 6.0, 2.0

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs("wheel", DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        self.n_agents = config["n_agents"]
        self.half = config["line_length"] / 2
        self.desired = config["desired_velocity"]
        inertia = config["line_mass"] * config["line_length"] ** 2 / 12
        #: torque that balances the line's drag at the desired speed (steady state of the Euler step)
        self.drag_torque = DRAG * inertia * self.desired / DT
        #: torque per rad/s of speed error that removes ``correction`` of it in one step
        self.torque_gain = self.correction * inertia / DT

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        vel = observation[:, 2:4]
        offset = -observation[:, 4:6]  # agent relative to the pivot
        end = observation[:, 6:8] - observation[:, 4:6]  # the first end relative to the pivot
        speed = observation[:, 11]
        radius = torch.linalg.vector_norm(offset, dim=-1).clamp_min(1e-6)
        radial = offset / radius.unsqueeze(-1)
        tangent = torch.stack([-radial[:, 1], radial[:, 0]], dim=-1)  # counter-clockwise

        # the arc from the agent's surface to the half-line ahead of it (counter-clockwise)
        side = radial[:, 0] * end[:, 1] - radial[:, 1] * end[:, 0]  # > 0: the first end is ahead
        ahead_cos = (radial * end).sum(-1) * torch.where(side >= 0, 1.0, -1.0)
        gap = torch.atan2(side.abs(), ahead_cos) * radius - AGENT_RADIUS - LINE_MIN_DIST
        closing = (self.approach_gain * gap).clamp(0.0, self.approach_speed)

        # feed-forward: this agent's share of the line's drag torque plus its own drag at the rim speed
        lever = radius.clamp(self.r_min * self.half, self.r_max * self.half)
        own_drag = DRAG * self.desired * lever / DT  # mass 1
        force = (self.drag_torque + self.torque_gain * (self.desired - speed)) / (self.n_agents * lever) + own_drag
        # own tangential speed minus the line's there, less the speed at which to close the gap
        slip = (vel * tangent).sum(-1) - speed * radius - closing
        push = force / AGENT_U_MULTIPLIER - self.contact_damping * slip
        floor = own_drag / AGENT_U_MULTIPLIER  # keep pace with the rim: stay in contact
        push = push.maximum(floor).clamp(max=u_range)

        radial_cmd = self.radial_gain * (lever - radius) - self.radial_damping * (vel * radial).sum(-1)
        action = push.unsqueeze(-1) * tangent + radial_cmd.unsqueeze(-1) * radial
        return action.clamp(-u_range, u_range)
