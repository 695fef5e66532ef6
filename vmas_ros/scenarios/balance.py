"""balance: agents carry a package on a free line up to a goal, under gravity.

Description
    ``n_agents`` discs (radius 0.03, force x0.7) start side by side at the
    bottom of a world with weak vertical gravity (0, -0.05) and a floor. A free
    line (length 0.8, mass 5, it can move and rotate) rests on them with a
    package (a disc of radius 0.05 and mass ``package_mass``) on top. Contacts
    are frictionless: the line and the package are only pushed along the
    line's normal. The team must lift the package to a goal disc in the upper
    half without dropping the line or the package on the floor (paper,
    "Multi-robot scenarios"). Positions are clamped to ``|y| <= 1``; there is no
    bound on x.
Observation (per agent, in this order)
    own position (2), own velocity (2), own position minus the package's (2),
    own position minus the line's centre (2), the package's position minus the
    goal's (2), the package's velocity (2), the line's velocity (2), the line's
    angular velocity (1) and its angle modulo pi (1): 16 values.
Reward
    Shared by all agents: 100 x the decrease, over the step, of the package's
    distance to the goal, plus -10 on every step on which the line or the
    package touches the floor. ``info`` gives both terms (``pos_rew``,
    ``ground_rew``).
Starting state
    Goal uniform in [-1, 1] x [0, 1]. The line level at height -1 + 0.06 with
    its centre's x uniform in [-0.6, 0.6]; the agents right under it, evenly
    spread from one end to the other; the package on the line, at an offset
    uniform over the line (or at its middle without
    ``random_package_pos_on_line``). Everything at rest.
Episode termination
    When the line or the package touches the floor, or the package touches
    the goal.
Kwargs
    ``n_agents`` (3, at least 2), ``package_mass`` (5),
    ``random_package_pos_on_line`` (True).
"""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios.common import continuous_heuristic_kwargs, read_kwargs
from vmas_ros.simulator.core import Agent, Box, Landmark, Line, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

AGENT_RADIUS = 0.03
AGENT_U_MULTIPLIER = 0.7
LINE_LENGTH = 0.8
LINE_MASS = 5.0
PACKAGE_RADIUS = 0.05  # goal too
GRAVITY = 0.05
Y_SEMIDIM = 1.0
FLOOR_LENGTH, FLOOR_WIDTH = 10.0, 1.0
DT = 0.1
FLOOR_TOP = -Y_SEMIDIM - AGENT_RADIUS
SHAPING_FACTOR = 100.0
FALL_REWARD = -10.0
#: name -> default of every kwarg (the heuristic takes them too)
DEFAULTS = {"n_agents": 3, "package_mass": 5.0, "random_package_pos_on_line": True}


def validate(config: dict) -> None:
    """Raise ValueError for a kwarg value the task cannot be built with."""
    if isinstance(config["n_agents"], bool) or not isinstance(config["n_agents"], int) or config["n_agents"] < 2:
        raise ValueError(f"balance: n_agents must be an int >= 2 (one under each end), got {config['n_agents']!r}")
    mass = config["package_mass"]
    if not (isinstance(mass, (int, float)) and mass > 0):
        raise ValueError(f"balance: package_mass must be a number > 0, got {mass!r}")
    if not isinstance(config["random_package_pos_on_line"], bool):
        raise ValueError(  # noqa: TRY004 (a bad kwarg value is a ValueError throughout the scenarios)
            f"balance: random_package_pos_on_line must be a bool, got {config['random_package_pos_on_line']!r}"
        )


def agent_slots(n_agents: int) -> torch.Tensor:
    """Where the agents start along the line, relative to its centre: [n_agents], evenly from end to end."""
    span = LINE_LENGTH - AGENT_RADIUS
    return torch.linspace(-span / 2, span / 2, n_agents)


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        validate(config)
        self.n_agents = config["n_agents"]
        self.package_mass = float(config["package_mass"])
        self.random_package_pos_on_line = config["random_package_pos_on_line"]
        self.visualize_semidims = False

        world = World(batch_dim, device, dt=DT, gravity=(0.0, -GRAVITY), y_semidim=Y_SEMIDIM)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), u_multiplier=AGENT_U_MULTIPLIER))
        goal = Landmark(name="goal", shape=Sphere(PACKAGE_RADIUS), collide=False, color=Color.LIGHT_GREEN)
        world.add_landmark(goal)
        self.package = Landmark(
            name="package", shape=Sphere(PACKAGE_RADIUS), collide=True, movable=True,
            mass=self.package_mass, color=Color.RED,
        )
        self.package.goal = goal
        world.add_landmark(self.package)
        self.line = Landmark(
            name="line", shape=Line(length=LINE_LENGTH), collide=True, movable=True, rotatable=True,
            mass=LINE_MASS, color=Color.BLACK,
        )
        world.add_landmark(self.line)
        self.floor = Landmark(
            name="floor", shape=Box(length=FLOOR_LENGTH, width=FLOOR_WIDTH), collide=True, color=Color.WHITE,
        )
        world.add_landmark(self.floor)

        # agents' offsets from the line's centre at the start: [n_agents, 2]
        slots = agent_slots(self.n_agents)
        self._agent_offsets = torch.stack([slots, torch.full_like(slots, -2 * AGENT_RADIUS)], dim=-1).to(world.device)
        #: 100 x the package's distance to the goal at the last reward (or reset), per env [B]
        self.shaping = torch.zeros(batch_dim, device=world.device)
        self._rewards: dict | None = None
        self._grounded = torch.zeros(batch_dim, dtype=torch.bool, device=world.device)
        return world

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = world.batch_dim if env_index is None else 1 if isinstance(env_index, int) else len(env_index)

        def uniform(low: float, high: float) -> torch.Tensor:
            return torch.empty(rows, 1, device=world.device).uniform_(low, high)

        def constant(value: float) -> torch.Tensor:
            return torch.full((rows, 1), value, device=world.device)

        goal = torch.cat([uniform(-1.0, 1.0), uniform(0.0, Y_SEMIDIM)], dim=1)
        reach = LINE_LENGTH / 2
        line = torch.cat([uniform(-1.0 + reach, 1.0 - reach), constant(-Y_SEMIDIM + 2 * AGENT_RADIUS)], dim=1)
        along = reach - PACKAGE_RADIUS
        package_x = uniform(-along, along) if self.random_package_pos_on_line else constant(0.0)
        package = line + torch.cat([package_x, constant(PACKAGE_RADIUS)], dim=1)
        floor = torch.tensor([0.0, FLOOR_TOP - FLOOR_WIDTH / 2], device=world.device)

        def put(entity, pos: torch.Tensor) -> None:
            entity.set_pos(pos[0] if isinstance(env_index, int) else pos, batch_index=env_index)

        for agent, offset in zip(world.agents, self._agent_offsets):
            put(agent, line + offset)
        put(self.line, line)
        put(self.package.goal, goal)
        put(self.package, package)
        put(self.floor, floor.expand(rows, 2))
        # world.reset has zeroed every velocity and angle in these envs: the line starts level

        self._grounded = self.on_the_ground()  # read by done() until the next reward
        distance = torch.linalg.vector_norm(package - goal, dim=-1) * SHAPING_FACTOR
        if env_index is None:
            self.shaping = distance
        else:
            self.shaping[env_index] = distance[0] if isinstance(env_index, int) else distance

    # ------------------------------------------------------------------ helpers
    def on_the_ground(self) -> torch.Tensor:
        """Whether the line or the package touches the floor, per env [B] bool."""
        return self.world.is_overlapping(self.line, self.floor) | self.world.is_overlapping(self.package, self.floor)

    def package_distance(self) -> torch.Tensor:
        """The package's distance to the goal, per env [B]."""
        return torch.linalg.vector_norm(self.package.state.pos - self.package.goal.state.pos, dim=-1)

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:  # one shared reward: compute it once per step
            shaping = self.package_distance() * SHAPING_FACTOR
            self._grounded = self.on_the_ground()
            ground = torch.where(self._grounded, FALL_REWARD, 0.0)
            self._rewards = {"pos_rew": self.shaping - shaping, "ground_rew": ground}
            self.shaping = shaping
        return self._rewards["ground_rew"] + self._rewards["pos_rew"]

    def observation(self, agent: Agent) -> torch.Tensor:
        pos, package, line = agent.state.pos, self.package.state, self.line.state
        return torch.cat([
            pos,
            agent.state.vel,
            pos - package.pos,
            pos - line.pos,
            package.pos - self.package.goal.state.pos,
            package.vel,
            line.vel,
            line.ang_vel,
            line.rot % math.pi,
        ], dim=-1)

    def done(self) -> torch.Tensor:
        # the floor test (the costly part) is the one of the last reward or reset: the env always
        # computes rewards before dones, and a reset recomputes it for every env
        return self._grounded | self.world.is_overlapping(self.package, self.package.goal)

    def info(self, agent: Agent) -> dict:
        if self._rewards is None:  # before the first step
            zeros = torch.zeros(self.world.batch_dim, device=self.world.device)
            return {"pos_rew": zeros, "ground_rew": zeros}
        return dict(self._rewards)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Lift the line evenly, steer the load by tilting the line, keep the package on it.

    Contacts are frictionless, so the line, and the package on it, are only
    pushed along the line's normal: the tilt of the line is the load's
    heading. Each agent reads the line's frame (tangent ``t``, normal ``n``)
    from the observed angle and:

    * keeps to its place in a formation under the line: the start layout
      pulled in by ``inset``, its inner places shifted towards the centre of
      mass of line and package (by less than half their spacing, so every
      agent stays nearest to its own place: the agent cannot see the others);
    * pushes along ``n`` with a common push (its share of the weight, plus a
      speed controller moving the load towards the goal at up to ``cruise``)
      and a share, proportional to its lever about the formation's centroid,
      of a torque that carries the load off that centroid (weight and drag
      both act at the centre of mass) and turns the line to the target tilt.
      The target tilt points the normal at the goal (at most ``max_tilt``,
      and never so steep that the low end touches the floor), corrected to
      roll the package back towards the middle of the line. The turn fades
      out as the line's speed along ``n`` falls short of the wanted speed (to
      nothing at a shortfall of ``cruise``): lift first, then turn. At the
      start the package bounces off the line and lands back on it; turning
      at once would take the push the line needs to catch it, and the
      package would sink, away from the goal, for a step or two (VMAS's own
      test requires its distance to the goal never to grow). The common push
      is kept far enough inside [``min_push``, u_range] for every torque share,
      so no agent lets go of the line or saturates;
    * damps its speed along the line relative to the line's.

    It needs ``n_agents`` and ``package_mass`` (scenario kwargs) to share the
    load; continuous actions only.
    """

    max_tilt = 0.5  # rad
    floor_margin = 0.04  # least clearance between the line's low end and the floor
    tilt_goal_floor = 0.3  # vertical distance below which the goal's bearing stops steepening
    centre_gain, centre_damping = 1.0, 10.0  # rad per unit of package offset / per unit/s of slide
    cruise, speed_gain, goal_gain = 0.1, 10.0, 0.5  # goal_gain: desired speed per unit of distance
    tilt_gain, spin_damping = 2.0, 2.0
    slot_gain, slot_damping = 4.0, 2.0
    min_push = 0.1  # the least push along the normal, so that no agent lets go of the line
    inset = 0.85

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        config = continuous_heuristic_kwargs("balance", DEFAULTS, scenario_kwargs, continuous_action)
        validate(config)
        self.n_agents = config["n_agents"]
        self.package_mass = float(config["package_mass"])
        slots = agent_slots(self.n_agents)
        #: the formation's places along the line with the package in the middle: [n_agents]
        self.places = self.inset * slots
        #: which places move towards the centre of mass (all but the two ends), and by at most how far
        self.inner = torch.ones(self.n_agents)
        self.inner[[0, -1]] = 0.0
        self.shift = 0.45 * float(self.places[1] - self.places[0])
        #: the part of the common push that goes into the load (the rest moves the agents themselves)
        self.load_share = (LINE_MASS + self.package_mass) / (LINE_MASS + self.package_mass + self.n_agents)
        # each agent's share of the weight of the line, the package and itself, as an action along n
        self.hover = ((LINE_MASS + self.package_mass) / self.n_agents + 1.0) * GRAVITY / AGENT_U_MULTIPLIER

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        o = observation
        vel, to_package, to_line = o[:, 2:4], -o[:, 4:6], -o[:, 6:8]
        to_goal, package_vel, line_vel = -o[:, 8:10], o[:, 10:12], o[:, 12:14]
        spin = o[:, 14]
        tilt = (o[:, 15] + math.pi / 2) % math.pi - math.pi / 2  # in [-pi/2, pi/2)
        tangent = torch.stack([torch.cos(tilt), torch.sin(tilt)], dim=-1)
        normal = torch.stack([-torch.sin(tilt), torch.cos(tilt)], dim=-1)

        def along(v: torch.Tensor, axis: torch.Tensor) -> torch.Tensor:
            return (v * axis).sum(-1)

        # positions along the line, from its centre
        own = -along(to_line, tangent)
        package = along(to_package - to_line, tangent)
        slide = along(package_vel - line_vel, tangent)
        mass_centre = package * self.package_mass / (LINE_MASS + self.package_mass)
        # the formation: the start layout pulled in, its inner places shifted towards the centre of mass
        shift = mass_centre.clamp(-self.shift, self.shift).unsqueeze(-1)
        places = self.places.to(o.device) + self.inner.to(o.device) * shift  # [B, n]
        place = places.gather(1, (places - own.unsqueeze(-1)).abs().argmin(dim=-1, keepdim=True))[:, 0]
        centroid = places.mean(dim=-1)
        lever = own - centroid
        lever_sum = (places - centroid.unsqueeze(-1)).pow(2).sum(dim=-1)  # sum of the agents' squared levers
        max_lever = (places - centroid.unsqueeze(-1)).abs().amax(dim=-1)

        # heading: point the normal at the goal, then roll the package back to the middle
        bearing = torch.atan2(-to_goal[:, 0], to_goal[:, 1].clamp_min(self.tilt_goal_floor))
        target_tilt = bearing + self.centre_gain * package + self.centre_damping * slide
        # no steeper than keeps the low end of the line off the floor
        height = o[:, 1] - o[:, 7] - FLOOR_TOP - self.floor_margin
        steepest = torch.asin((height / (LINE_LENGTH / 2)).clamp(0.0, math.sin(self.max_tilt)))
        target_tilt = target_tilt.maximum(-steepest).minimum(steepest)

        # common push: hold the weight, plus a speed controller along the normal towards the goal
        rise = along(line_vel, normal)
        wanted_speed = (self.goal_gain * along(to_goal, normal)).clamp(-self.cruise, self.cruise)
        common = self.hover / torch.cos(tilt) + self.speed_gain * (wanted_speed - rise)
        # torque about the formation's centroid: carry the load (weight and drag, both acting at the
        # centre of mass, where the common pushes would hold it), and turn the line to the target tilt,
        # the less the more the line's speed along n falls short of the wanted one (lift first)
        carry = self.load_share * self.n_agents * common.clamp(0.0, u_range) * (mass_centre - centroid)
        ready = (1.0 - (wanted_speed - rise) / self.cruise).clamp(0.0, 1.0)
        torque = carry + ready * self.tilt_gain * (target_tilt - tilt) - self.spin_damping * spin
        most = (u_range - self.min_push) / 2 * lever_sum / max_lever
        torque = torque.maximum(-most).minimum(most)
        # keep the common push far enough inside [min_push, u_range] for every agent's torque share
        spread = torque.abs() * max_lever / lever_sum
        common = common.maximum(self.min_push + spread).minimum(u_range - spread)
        push = (common + torque * lever / lever_sum).clamp(0.0, u_range)

        hold = self.slot_gain * (place - own) - self.slot_damping * along(vel - line_vel, tangent)
        action = push.unsqueeze(-1) * normal + hold.unsqueeze(-1) * tangent
        return action.clamp(-u_range, u_range)
