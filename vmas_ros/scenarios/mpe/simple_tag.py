"""simple_tag (MPE "predator-prey"): slow adversaries chase fast good agents.

Description
    ``num_adversaries`` red predators (radius 0.075, force x3, top speed 1.0)
    hunt ``num_good_agents`` green prey (radius 0.05, force x4, top speed 1.3)
    among ``num_landmarks`` black obstacles (radius 0.2) inside walls at
    ``+-bound``. A catch is a predator and a prey overlapping.
Observation (per agent, in this order)
    own velocity (2, if ``observe_vel``), own position (2, if ``observe_pos``),
    every obstacle's position relative to the agent (2 x n_landmarks), the
    relative position of every other agent it sees (2 each, in agent order:
    adversaries first), then the velocity of every good agent among those (2
    each). Everyone sees the other team; with ``observe_same_team`` (default)
    agents also see their own team.
Reward
    Per catch, +10 to the adversary and -10 to the prey (only for agents with
    ``collide``). ``shape_agent_rew`` adds 0.1 x the prey's summed distance to
    the adversaries; ``shape_adversary_rew`` subtracts 0.1 x the adversary's
    distance to its nearest prey. With ``adversaries_share_rew`` (default) every
    adversary gets its team's sum; ``agents_share_rew`` does the same for prey.
    Unlike MPE there is no out-of-bounds penalty: walls keep agents in.
Starting state
    Agents uniform in [-bound, bound]^2, obstacles in [-(bound - 0.1), bound - 0.1]^2.
    With ``respawn_at_catch`` a caught prey reappears at a uniform random point
    at rest, right after the rewards of the catch are computed.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``num_good_agents`` (1), ``num_adversaries`` (3), ``num_landmarks`` (2),
    ``shape_agent_rew`` (False), ``shape_adversary_rew`` (False),
    ``agents_share_rew`` (False), ``adversaries_share_rew`` (True),
    ``observe_same_team`` (True), ``observe_pos`` (True), ``observe_vel`` (True),
    ``bound`` (1.0), ``respawn_at_catch`` (False).
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario
from vmas_ros.simulator.utils import Color

GOOD_RADIUS, ADVERSARY_RADIUS, OBSTACLE_RADIUS = 0.05, 0.075, 0.2
CATCH_REWARD = 10.0
SHAPING_WEIGHT = 0.1
#: name -> default of every kwarg (the heuristic reads the layout ones too)
DEFAULTS = dict(
    num_good_agents=1, num_adversaries=3, num_landmarks=2, shape_agent_rew=False, shape_adversary_rew=False,
    agents_share_rew=False, adversaries_share_rew=True, observe_same_team=True, observe_pos=True,
    observe_vel=True, bound=1.0, respawn_at_catch=False,
)


def uniform_positions(world: World, env_index, low: float, high: float) -> torch.Tensor:
    """Uniform positions shaped for ``set_pos(..., batch_index=env_index)``."""
    rows = world.batch_dim if env_index is None else 1 if isinstance(env_index, int) else len(env_index)
    pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(low, high)
    return pos[0] if isinstance(env_index, int) else pos


def seen_agents(is_adversary: list, observer: int, same_team: bool) -> tuple:
    """Indices of the agents ``observer`` sees by position, and of those it sees by velocity (the prey)."""
    positions = [
        j for j in range(len(is_adversary))
        if j != observer and (same_team or is_adversary[j] != is_adversary[observer])
    ]
    return positions, [j for j in positions if not is_adversary[j]]


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = read_kwargs(kwargs, DEFAULTS)
        for name in ("num_good_agents", "num_adversaries"):
            if not isinstance(config[name], int) or config[name] < 1:
                raise ValueError(f"simple_tag: {name} must be an int >= 1, got {config[name]!r}")
        if not isinstance(config["num_landmarks"], int) or config["num_landmarks"] < 0:
            raise ValueError(f"simple_tag: num_landmarks must be an int >= 0, got {config['num_landmarks']!r}")
        if not config["bound"] > 0:
            raise ValueError(f"simple_tag: bound must be > 0, got {config['bound']!r}")
        for name, value in config.items():
            setattr(self, name, value)
        self.visualize_semidims = False  # extra_render draws the walls

        world = World(
            batch_dim=batch_dim, device=device, x_semidim=self.bound, y_semidim=self.bound,
            substeps=10, collision_force=500,
        )
        roles = [True] * self.num_adversaries + [False] * self.num_good_agents
        for i, adversary in enumerate(roles):
            world.add_agent(Agent(
                name=f"adversary_{i}" if adversary else f"agent_{i - self.num_adversaries}",
                collide=True,
                shape=Sphere(radius=ADVERSARY_RADIUS if adversary else GOOD_RADIUS),
                u_multiplier=3.0 if adversary else 4.0,
                max_speed=1.0 if adversary else 1.3,
                color=Color.RED if adversary else Color.GREEN,
                adversary=adversary,
            ))
        for i in range(self.num_landmarks):
            world.add_landmark(Landmark(
                name=f"landmark {i}", collide=True, shape=Sphere(radius=OBSTACLE_RADIUS), color=Color.BLACK,
            ))

        self._adversary = torch.tensor(roles, device=device)
        self._index = {agent.name: i for i, agent in enumerate(world.agents)}
        self._seen = [seen_agents(roles, i, self.observe_same_team) for i in range(len(roles))]  # index lists
        self._rewards: torch.Tensor | None = None
        return world

    def reset_world_at(self, env_index=None) -> None:
        for agent in self.world.agents:
            agent.set_pos(uniform_positions(self.world, env_index, -self.bound, self.bound), batch_index=env_index)
        margin = self.bound - 0.1
        for landmark in self.world.landmarks:
            landmark.set_pos(uniform_positions(self.world, env_index, -margin, margin), batch_index=env_index)

    # ------------------------------------------------------------------ helpers
    def _stack(self, field: str) -> torch.Tensor:
        """``field`` of every agent, [B, n_agents, 2]."""
        return torch.stack([getattr(a.state, field) for a in self.world.agents], dim=1)

    def _catches(self, pos: torch.Tensor) -> tuple:
        """Which predator overlaps which prey ([B, A, G] bool) and their distances ([B, A, G])."""
        adv, good = self._adversary, ~self._adversary
        radii = torch.tensor([a.shape.radius for a in self.world.agents], device=pos.device)
        gap = torch.linalg.vector_norm(pos[:, adv].unsqueeze(2) - pos[:, good].unsqueeze(1), dim=-1)
        return gap < radii[adv].unsqueeze(1) + radii[good].unsqueeze(0), gap

    # ------------------------------------------------------------------ reward
    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:
            self._rewards = self._team_rewards()
        return self._rewards[:, self._index[agent.name]]

    def _team_rewards(self) -> torch.Tensor:
        """Every agent's reward, [B, n_agents]; respawns caught prey afterwards if asked to."""
        adv, good = self._adversary, ~self._adversary
        pos = self._stack("pos")
        caught, gap = self._catches(pos)  # [B, A, G]
        collide = torch.tensor([a.collide for a in self.world.agents], device=pos.device)
        good_rew = -CATCH_REWARD * caught.sum(dim=1) * collide[good]
        adv_rew = CATCH_REWARD * caught.sum(dim=2) * collide[adv]
        if self.shape_agent_rew:
            good_rew = good_rew + SHAPING_WEIGHT * gap.sum(dim=1)
        if self.shape_adversary_rew:
            adv_rew = adv_rew - SHAPING_WEIGHT * gap.amin(dim=2)
        if self.agents_share_rew:
            good_rew = good_rew.sum(dim=1, keepdim=True).expand_as(good_rew)
        if self.adversaries_share_rew:
            adv_rew = adv_rew.sum(dim=1, keepdim=True).expand_as(adv_rew)
        rewards = torch.empty(pos.shape[:2], device=pos.device)
        rewards[:, adv], rewards[:, good] = adv_rew.float(), good_rew.float()
        if self.respawn_at_catch:
            self._respawn(caught.any(dim=1))
        return rewards

    def _respawn(self, caught: torch.Tensor) -> None:
        """Move each caught prey ([B, n_good] mask) to a fresh random spot, at rest."""
        prey = [a for a in self.world.agents if not a.adversary]
        fresh = torch.empty(caught.shape + (2,), device=caught.device).uniform_(-self.bound, self.bound)
        for k, agent in enumerate(prey):
            hit = caught[:, k].unsqueeze(-1)
            agent.set_pos(torch.where(hit, fresh[:, k], agent.state.pos), batch_index=None)
            agent.set_vel(torch.where(hit, 0.0, agent.state.vel), batch_index=None)

    # ------------------------------------------------------------- observation
    def observation(self, agent: Agent) -> torch.Tensor:
        seen_pos, seen_vel = self._seen[self._index[agent.name]]
        own = agent.state.pos.unsqueeze(1)
        parts = ([agent.state.vel] if self.observe_vel else []) + ([agent.state.pos] if self.observe_pos else [])
        if self.world.landmarks:
            landmarks = torch.stack([l.state.pos for l in self.world.landmarks], dim=1)
            parts.append((landmarks - own).flatten(1))
        parts.append((self._stack("pos")[:, seen_pos] - own).flatten(1))
        parts.append(self._stack("vel")[:, seen_vel].flatten(1))
        return torch.cat(parts, dim=-1)

    def extra_render(self, env_index: int = 0) -> list:
        from vmas_ros.simulator import rendering

        edge = self.bound + ADVERSARY_RADIUS
        walls = rendering.make_polygon([(-edge, -edge), (edge, -edge), (edge, edge), (-edge, edge)], filled=False)
        walls.set_color(*Color.BLACK.value)
        return [walls]


class HeuristicPolicy(BaseHeuristicPolicy):
    """Predators pursue the nearest prey; prey flee the nearest predator and keep off walls and obstacles.

    The observation layout depends on the scenario's kwargs, so the policy
    takes the same kwargs (defaults match the scenario's). An agent's role is
    read from its observation width (a predator sees the prey's velocities, a
    prey its own team's); when both roles have the same width (possible only
    with ``observe_same_team=False``) pass ``role="adversary"`` or ``"good"``.

    Predator: full thrust towards where the nearest prey will be after
    ``lead`` x distance seconds (its velocity is in the observation).
    Prey: full thrust along the sum of a unit vector away from the nearest
    predator, a push back from walls within ``wall_margin`` of ``bound`` (needs
    ``observe_pos``), and a push away from obstacles closer than ``clearance``.
    """

    lead = 0.5
    wall_margin = 0.3
    wall_gain = 2.0
    clearance = 0.3

    def __init__(self, continuous_action: bool = True, role: str | None = None, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        unknown = set(scenario_kwargs) - set(DEFAULTS)
        if unknown:
            raise TypeError(f"simple_tag HeuristicPolicy got unknown kwargs {sorted(unknown)}")
        if role not in (None, "adversary", "good"):
            raise ValueError(f"role must be None, 'adversary' or 'good', got {role!r}")
        cfg = {**DEFAULTS, **scenario_kwargs}
        n_adv, n_good, team = cfg["num_adversaries"], cfg["num_good_agents"], cfg["observe_same_team"]
        self.bound, self.observe_pos = cfg["bound"], cfg["observe_pos"]
        self.head = 2 * cfg["observe_vel"]  # where own position would start
        self.n_landmarks = cfg["num_landmarks"]
        self.layouts = {}
        for name, observer in (("adversary", 0), ("good", n_adv)):
            roles = [True] * n_adv + [False] * n_good
            seen_pos, seen_vel = seen_agents(roles, observer, team)
            width = self.head + 2 * cfg["observe_pos"] + 2 * self.n_landmarks + 2 * len(seen_pos) + 2 * len(seen_vel)
            self.layouts[name] = (width, torch.tensor([roles[j] for j in seen_pos]), len(seen_vel))
        self.role = role
        if role is None and self.layouts["adversary"][0] == self.layouts["good"][0]:
            raise ValueError("simple_tag: both roles have the same observation width with these kwargs; pass role=")

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        role = self.role or ("adversary" if observation.shape[1] == self.layouts["adversary"][0] else "good")
        width, seen_adv, n_vel = self.layouts[role]
        if observation.shape[1] != width:
            raise ValueError(f"simple_tag heuristic: observation width {observation.shape[1]} fits neither role")
        batch, start = observation.shape[0], self.head + 2 * self.observe_pos
        landmarks = observation[:, start:start + 2 * self.n_landmarks].view(batch, -1, 2)
        start += 2 * self.n_landmarks
        others = observation[:, start:start + 2 * len(seen_adv)].view(batch, -1, 2)
        seen_adv = seen_adv.to(observation.device)
        if role == "adversary":
            prey_vel = observation[:, width - 2 * n_vel:].view(batch, -1, 2)
            direction = self._pursue(others[:, ~seen_adv], prey_vel)
        else:
            own_pos = observation[:, self.head:self.head + 2] if self.observe_pos else None
            direction = self._flee(others[:, seen_adv], landmarks, own_pos)
        unit = direction / torch.linalg.vector_norm(direction, dim=-1, keepdim=True).clamp_min(1e-6)
        return unit * u_range

    def _pursue(self, prey: torch.Tensor, prey_vel: torch.Tensor) -> torch.Tensor:
        dist = torch.linalg.vector_norm(prey, dim=-1)  # [B, G]
        target = dist.argmin(dim=1)
        rows = torch.arange(prey.shape[0], device=prey.device)
        lead = self.lead * dist[rows, target].unsqueeze(-1)
        return prey[rows, target] + lead * prey_vel[rows, target]

    def _flee(self, hunters: torch.Tensor, landmarks: torch.Tensor, own_pos: torch.Tensor | None) -> torch.Tensor:
        dist = torch.linalg.vector_norm(hunters, dim=-1)  # [B, A]
        nearest = hunters[torch.arange(hunters.shape[0], device=hunters.device), dist.argmin(dim=1)]
        direction = -nearest / torch.linalg.vector_norm(nearest, dim=-1, keepdim=True).clamp_min(1e-6)
        if own_pos is not None:
            depth = ((own_pos.abs() - (self.bound - self.wall_margin)) / self.wall_margin).clamp_min(0.0)
            direction = direction - self.wall_gain * depth * own_pos.sign()
        if landmarks.shape[1]:
            gap = torch.linalg.vector_norm(landmarks, dim=-1, keepdim=True).clamp_min(1e-6)
            push = ((self.clearance + OBSTACLE_RADIUS - gap) / self.clearance).clamp_min(0.0)
            direction = direction - (push * landmarks / gap).sum(dim=1)
        return direction
