"""transport: a team pushes heavy boxes onto a goal disc.

Description
    ``n_agents`` small discs (radius 0.03, force x0.6) must push ``n_packages``
    heavy boxes (``package_length`` along x by ``package_width`` along y, mass
    ``package_mass``, not rotatable) onto one goal disc of radius 0.15 (paper,
    "Multi-robot scenarios"). A default package weighs 50 agents: one agent
    barely moves it, so the team has to push together. The world is walled at
    ``+-(1 + 0.06 + max(package_length, package_width))`` so that agents can
    always get behind a package spawned near the edge.
Observation (per agent, in this order)
    own position (2), own velocity (2), then per package: its position relative
    to the goal (2), its position relative to the agent (2), its velocity (2),
    and 1.0 if it is on the goal else 0.0 (1). Width ``4 + 7 * n_packages``.
Reward
    Shared by the team. Per package not on the goal after the step, 100 x the
    decrease of its distance to the goal over the step; summed over packages.
    A package is on the goal while its box overlaps the goal disc; it then turns
    green.
Starting state
    Agents uniform in [-1, 1]^2, at least 0.06 apart; then the goal and the
    packages uniform in [-1, 1]^2, each at least (package half-diagonal + 0.16)
    from every agent, from the goal and from each other, so no package starts
    on the goal or touching an agent. All at rest.
Episode termination
    When every package is on the goal.
Kwargs
    ``n_agents`` (4), ``n_packages`` (1), ``package_width`` (0.15),
    ``package_length`` (0.15), ``package_mass`` (50).
"""
from __future__ import annotations

import math

import torch

from vmas_ros.scenarios import packages as pk
from vmas_ros.scenarios.common import check_int, check_number, read_kwargs, selected_rows
from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.core import Agent, Box, Landmark, Sphere, World
from vmas_ros.simulator.layout import cat_columns, join_xy
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

AGENT_RADIUS = 0.03
AGENT_U_MULTIPLIER = 0.6
GOAL_RADIUS = 0.15
SHAPING_FACTOR = 100.0
#: agents, goal and packages spawn in [-SPAWN_HALF_SIDE, SPAWN_HALF_SIDE]^2
SPAWN_HALF_SIDE = 1.0
#: observation columns per package: offset from goal (2), offset from agent (2), velocity (2), on goal (1)
PACKAGE_BLOCK = 7
#: observation columns before the packages: own position (2) and velocity (2)
OWN_BLOCK = 4
NAME = "transport"
DEFAULTS = {"n_agents": 4, "n_packages": 1, "package_width": 0.15, "package_length": 0.15, "package_mass": 50.0}


class Scenario(BaseScenario):
    supports_batched_reset = True
    fresh_observations = True  # views of one result computed per collection, never written to

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        options = read_kwargs(kwargs, DEFAULTS)
        self.n_agents = check_int(NAME, "n_agents", options["n_agents"])
        self.n_packages = check_int(NAME, "n_packages", options["n_packages"])
        self.package_width = check_number(NAME, "package_width", options["package_width"], 0.0, strict=True)
        self.package_length = check_number(NAME, "package_length", options["package_length"], 0.0, strict=True)
        self.package_mass = check_number(NAME, "package_mass", options["package_mass"], 0.0, strict=True)

        wall = SPAWN_HALF_SIDE + 2 * AGENT_RADIUS + max(self.package_length, self.package_width)
        world = World(batch_dim, device, x_semidim=wall, y_semidim=wall)
        for i in range(self.n_agents):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(AGENT_RADIUS), u_multiplier=AGENT_U_MULTIPLIER))
        self.goal = Landmark(name="goal", collide=False, shape=Sphere(radius=GOAL_RADIUS), color=Color.LIGHT_GREEN)
        world.add_landmark(self.goal)
        self.packages = []
        for i in range(self.n_packages):
            package = Landmark(
                name=f"package {i}", collide=True, movable=True, mass=self.package_mass,
                shape=Box(length=self.package_length, width=self.package_width), color=Color.RED,
            )
            package.goal = self.goal
            self.packages.append(package)
            world.add_landmark(package)
        # a package clears the goal, the agents and the other packages by 1 cm at spawn
        self.spawn_gap = self.packages[0].shape.circumscribed_radius() + GOAL_RADIUS + 0.01

        #: 100 x each package's distance to the goal when last scored, [B, P]
        self.potential = torch.zeros(batch_dim, self.n_packages, device=world.device)
        #: whether each package overlaps the goal, as of the last reward (or reset), [B, P]
        self.on_goal = torch.zeros(batch_dim, self.n_packages, dtype=torch.bool, device=world.device)
        self._reward = torch.zeros(batch_dim, device=world.device)
        self._agent_index = {agent.name: i for i, agent in enumerate(world.agents)}
        return world

    # ------------------------------------------------------------------- reset
    def reset_world_at(self, env_index: pk.EnvIndex = None) -> None:
        world = self.world
        rows = selected_rows(world.batch_dim, env_index)
        bounds = {"low": (-SPAWN_HALF_SIDE,) * 2, "high": (SPAWN_HALF_SIDE,) * 2, "device": world.device}
        agents = pk.spawn_apart(rows, self.n_agents, 2 * AGENT_RADIUS, what="agents", **bounds)
        landmarks = pk.spawn_apart(
            rows, 1 + self.n_packages, self.spawn_gap, occupied=agents, what="goal and packages", **bounds
        )
        for entity, pos in zip(world.agents + [self.goal] + self.packages, torch.cat([agents, landmarks], 1).unbind(1)):
            pk.place(entity, pos, env_index)
        distance, on_goal = self._package_status()
        if env_index is None:
            self.potential, self.on_goal = distance * SHAPING_FACTOR, on_goal
        else:
            self.potential[env_index] = distance[env_index] * SHAPING_FACTOR
            self.on_goal[env_index] = on_goal[env_index]
        self._paint()

    # ---------------------------------------------------------------- helpers
    def _package_pos(self) -> torch.Tensor:
        return torch.stack([p.state.pos for p in self.packages], dim=1)  # [B, P, 2]

    def batched_outputs(self, q: torch.Tensor, v: torch.Tensor) -> tuple:
        """``(distance [B, P], on_goal [B, P], observations [A, B, obs])`` from the planar state ``[3, N, B]``:
        the packages' status for the reward and every agent's observation, in one pass."""
        return state_outputs(q, v, self.n_packages, self.package_length, self.package_width)

    def _package_status(self):
        """Each package's distance to the goal and whether it overlaps it, both [B, P] (see :func:`package_status`)."""
        distance, on_goal, _ = self.outputs()
        return distance, on_goal

    def _paint(self) -> None:
        for package, color in zip(self.packages, pk.package_colors(self.on_goal).unbind(1)):
            package.color = color

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        """The team's reward, computed once per step (when asked for the first agent)."""
        if agent is self.world.agents[0]:
            distance, on_goal = self._package_status()
            potential = distance * SHAPING_FACTOR
            self._reward = pk.delivery_reward(self.potential, potential, on_goal)
            self.potential, self.on_goal = potential, on_goal
            self._paint()
        return self._reward

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> torch.Tensor:
        return self._observations()[self._agent_index[agent.name]]

    def _observations(self) -> torch.Tensor:
        """Every agent's observation ``[A, B, obs]``, computed once per state (see :func:`state_outputs`).

        Their delivered flags are the state's own, which ``on_goal`` holds
        once the state's reward (or reset) has been computed.
        """
        return self.outputs()[2]

    def done(self) -> torch.Tensor:
        return self.on_goal.all(dim=-1)


def package_status(q: torch.Tensor, n_packages: int, length: float, width: float) -> tuple:
    """Each package's distance to the goal and whether it overlaps it, both ``[B, P]``, from the planar state.

    ``q`` ``[3, N, B]`` with the goal first, then the packages. The test of
    ``World.is_overlapping`` (``geometry.disc_box_overlap_xy``) with the box
    boundary found in the box frame: equal to float rounding, in a fraction of
    the passes.
    """
    px, py, rot = q[0, 1 : 1 + n_packages], q[1, 1 : 1 + n_packages], q[2, 1 : 1 + n_packages]
    gx, gy = q[0, :1], q[1, :1]
    distance, on_goal = geo.disc_box_overlap_xy(
        px, py, rot, px.new_tensor(length), px.new_tensor(width), gx, gy, GOAL_RADIUS, exact=False
    )
    return distance.T, on_goal.T


def state_outputs(q: torch.Tensor, v: torch.Tensor, n_packages: int, length: float, width: float) -> tuple:
    """``(distance [B, P], on_goal [B, P], observations [A, B, obs])`` from the planar state ``[3, N, B]``.

    What ``Scenario.batched_outputs`` computes: one pure function of the state
    for the reward's status and all observations.
    """
    distance, on_goal = package_status(q, n_packages, length, width)
    pos, vel = join_xy(q[0], q[1]), join_xy(v[0], v[1])  # [N, B, 2]: the goal, packages, agents
    return distance, on_goal, observations(pos, vel, on_goal, n_packages)


def observations(pos: torch.Tensor, vel: torch.Tensor, on_goal: torch.Tensor, n_packages: int) -> torch.Tensor:
    """Every agent's observation ``[A, B, obs]`` from the stacked state ``[N, B, 2]`` (goal, packages, agents):
    its own position and velocity, then per package (offset from the goal, offset from the agent, velocity,
    delivered)."""
    packages, agents = pos[1 : 1 + n_packages], pos[1 + n_packages :]  # [P, B, 2], [A, B, 2]
    n_agents, batch = agents.shape[:2]
    blocks = cat_columns([
        (packages - pos[0]).transpose(0, 1).unsqueeze(0),
        (packages.unsqueeze(0) - agents.unsqueeze(1)).permute(0, 2, 1, 3),
        vel[1 : 1 + n_packages].transpose(0, 1).unsqueeze(0),
        on_goal.to(pos.dtype).unsqueeze(-1).unsqueeze(0),
    ], (n_agents, batch, n_packages))  # [A, B, P, PACKAGE_BLOCK]
    return cat_columns([agents, vel[1 + n_packages :], blocks.flatten(2)], (n_agents, batch))


class HeuristicPolicy(BaseHeuristicPolicy):
    """Get behind the package, on the side away from the goal, and push it through its centre.

    Every agent works on the same package: the undelivered one nearest the
    goal (all agents see the same package-goal offsets, so they agree without
    talking). Packages never rotate, so an agent knows the box's outline from
    the kwargs alone.

    * Behind it (within ``push_cone`` of the direction pointing away from the
      goal) the agent heads for the point where the package-goal line leaves
      the box's back, aiming a little past the surface so that it keeps
      pressing; agents queued behind the first ones push through them.
    * Elsewhere it circles the package at ``orbit_radius`` towards the back,
      aiming each step at the point of that circle ``orbit_step`` further
      round. That chord stays clear of the box (the radius is chosen so), so
      an agent never shoves the package towards the wrong side on its way.
    * Once every package is delivered it stops.
    """

    push_cone = math.radians(40.0)
    orbit_step = math.radians(45.0)
    clearance = 0.02
    push_depth = 0.05

    def __init__(
        self, continuous_action: bool = True, package_width: float = DEFAULTS["package_width"],
        package_length: float = DEFAULTS["package_length"],
    ) -> None:
        super().__init__(continuous_action)
        self.half_length = check_number(NAME, "package_length", package_length, 0.0, strict=True) / 2
        self.half_width = check_number(NAME, "package_width", package_width, 0.0, strict=True) / 2
        reach = math.hypot(self.half_length, self.half_width) + AGENT_RADIUS
        self.orbit_radius = reach / math.cos(self.orbit_step / 2) + self.clearance

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch, width = observation.shape
        n_packages, extra = divmod(width - OWN_BLOCK, PACKAGE_BLOCK)
        if n_packages < 1 or extra:
            raise ValueError(f"transport heuristic: observation width {width} is not 4 + 7 * n_packages")
        blocks = observation[:, OWN_BLOCK:].reshape(batch, n_packages, PACKAGE_BLOCK)
        from_goal, to_package, delivered = blocks[..., 0:2], blocks[..., 2:4], blocks[..., 6] > 0.5
        # the undelivered package nearest the goal
        remaining = torch.linalg.vector_norm(from_goal, dim=-1).masked_fill(delivered, float("inf"))
        rows = torch.arange(batch, device=observation.device)
        chosen = remaining.argmin(dim=1)
        forward = pk.unit(-from_goal[rows, chosen])  # package -> goal
        me = -to_package[rows, chosen]  # agent relative to the package centre

        # push: aim past the middle of the back surface
        support = self.half_length * forward[:, 0].abs() + self.half_width * forward[:, 1].abs()
        back = -forward * (support + AGENT_RADIUS).unsqueeze(-1)
        push = pk.unit(back + forward * self.push_depth - me)
        behind = (pk.unit(me) * -forward).sum(dim=-1) >= math.cos(self.push_cone)

        # orbit: towards the back along the circle, one bounded step of bearing at a time
        bearing = torch.atan2(me[:, 1], me[:, 0])
        turn = torch.atan2(-forward[:, 1], -forward[:, 0]) - bearing
        turn = torch.atan2(torch.sin(turn), torch.cos(turn)).clamp(-self.orbit_step, self.orbit_step)
        waypoint = self.orbit_radius * torch.stack([torch.cos(bearing + turn), torch.sin(bearing + turn)], dim=-1)
        orbit = pk.unit(waypoint - me)

        direction = torch.where(behind.unsqueeze(-1), push, orbit)
        direction = torch.where(delivered.all(dim=1, keepdim=True), 0.0, direction)
        return pk.scale_to_range(direction, u_range)
