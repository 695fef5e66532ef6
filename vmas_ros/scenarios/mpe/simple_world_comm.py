"""simple_world_comm (MPE predator-prey with a speaking leader, food and forests).

Description
    ``num_adversaries`` slow red predators hunt ``num_good_agents`` fast green
    prey in a walled 2x2 arena (``x_semidim = y_semidim = 1``). Prey score by
    standing on food. Grey obstacles (``landmark i``) block everyone; food and
    forests are not solid. Predator 0, the darker leader, is the only agent
    that sees other agents and the only one that speaks (``dim_c = 4``);
    every predator hears it.
Observation (per agent, in this order)
    own velocity (2), own position (2), every landmark's position relative to
    the agent (2 x (num_landmarks + num_food + num_forests), obstacles, food,
    then forests), then for every other agent, repeated once per forest, its
    relative position (2 x (n - 1) x num_forests), then likewise its velocity
    (prey only, zeros for predators), then ``in_forest`` (num_forests), and,
    for predators only, the leader's last message (4).
    As in VMAS 1.5 (unlike MPE) forests hide nothing and are not reported:
    the leader sees every other agent, everyone else gets zeros in those
    slots, and ``in_forest`` is always -1.
Reward
    prey: -5 per predator touching it, +2 per food it is on, and
    -0.05 x its distance to the nearest food.
    predators (shared): +5 per touching (prey, predator) pair. Unlike MPE
    there is no -0.1 x distance-to-nearest-prey shaping (VMAS 1.5's term is
    identically zero) and no out-of-bounds penalty for prey (walls instead).
Starting state
    Agents uniform in [-1, 1]^2, landmarks, food and forests in [-0.9, 0.9]^2.
Episode termination
    Never (set ``max_steps``).
Kwargs
    ``num_good_agents`` (2), ``num_adversaries`` (4, leader included),
    ``num_landmarks`` (1 obstacle), ``num_food`` (2), ``num_forests`` (2).
"""
from __future__ import annotations

import torch

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.simulator.core import Agent, Landmark, Sphere, World
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy
from vmas_ros.simulator.scenario import BaseScenario

DIM_C = 4
DEFAULTS = dict(num_good_agents=2, num_adversaries=4, num_landmarks=1, num_food=2, num_forests=2)
MINIMUM = dict(num_good_agents=1, num_adversaries=1, num_landmarks=0, num_food=1, num_forests=1)
PREY = dict(radius=0.045, u_multiplier=4.0, max_speed=1.3, color=(0.45, 0.95, 0.45))
PREDATOR = dict(radius=0.075, u_multiplier=3.0, max_speed=1.0, color=(0.95, 0.45, 0.45))
LEADER_COLOR = (0.65, 0.15, 0.15)
OBSTACLE = dict(radius=0.2, collide=True, color=(0.25, 0.25, 0.25))
FOOD = dict(radius=0.03, collide=False, color=(0.15, 0.15, 0.65))
FOREST = dict(radius=0.3, collide=False, color=(0.6, 0.9, 0.6))
CATCH_REWARD, FOOD_REWARD, FOOD_DISTANCE_WEIGHT = 5.0, 2.0, 0.05


def _stack(entities, field: str = "pos") -> torch.Tensor:
    """[batch, len(entities), 2] stack of one state field."""
    return torch.stack([getattr(e.state, field) for e in entities], dim=1)


def _touching(a_pos, a_radius, b_pos, b_radius) -> torch.Tensor:
    """[batch, A, B] bool: which pairs of discs overlap (strictly)."""
    gaps = torch.linalg.vector_norm(a_pos.unsqueeze(2) - b_pos.unsqueeze(1), dim=-1)
    return gaps < a_radius.view(1, -1, 1) + b_radius.view(1, 1, -1)


def _nearest(points: torch.Tensor) -> torch.Tensor:
    """The point of [batch, K, 2] closest to the origin, [batch, 2]."""
    pick = points.norm(dim=-1).argmin(dim=1).view(-1, 1, 1).expand(-1, 1, 2)
    return points.gather(1, pick).squeeze(1)


def _check_layout(layout: dict) -> None:
    for name, value in layout.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < MINIMUM[name]:
            raise ValueError(f"simple_world_comm: {name} must be an int >= {MINIMUM[name]}, got {value!r}")


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        layout = read_kwargs(kwargs, DEFAULTS)
        _check_layout(layout)
        world = World(batch_dim=batch_dim, device=device, x_semidim=1, y_semidim=1, dim_c=DIM_C)
        for i in range(layout["num_adversaries"]):
            spec = dict(PREDATOR, color=LEADER_COLOR if i == 0 else PREDATOR["color"])
            world.add_agent(self._agent("lead_adversary_0" if i == 0 else f"adversary_{i}", spec, True, i == 0))
        for i in range(layout["num_good_agents"]):
            world.add_agent(self._agent(f"agent_{i}", PREY, False, False))
        self.obstacles = self._landmarks(world, "landmark", layout["num_landmarks"], OBSTACLE)
        self.food = self._landmarks(world, "food", layout["num_food"], FOOD)
        self.forests = self._landmarks(world, "forest", layout["num_forests"], FOREST)
        self.leader = world.agents[0]
        self.predators = [a for a in world.agents if a.adversary]
        self.prey = [a for a in world.agents if not a.adversary]
        radii = lambda entities: torch.tensor([e.shape.radius for e in entities], device=device)  # noqa: E731
        self.predator_radius, self.prey_radius = radii(self.predators), radii(self.prey)
        self.food_radius = radii(self.food)
        n_agents = len(world.agents)
        self._index = {agent: i for i, agent in enumerate(world.agents)}
        #: row i: the indices of every agent but agent i, in world order, [n, n - 1]
        self.others = torch.stack([torch.cat([torch.arange(i), torch.arange(i + 1, n_agents)]) for i in range(n_agents)]).to(device)
        self.is_prey = torch.tensor([not a.adversary for a in world.agents], device=device)
        self._reward_cache = None
        return world

    @staticmethod
    def _landmarks(world: World, name: str, count: int, spec: dict) -> list:
        group = [
            Landmark(name=f"{name} {i}", collide=spec["collide"], shape=Sphere(radius=spec["radius"]), color=spec["color"])
            for i in range(count)
        ]
        for landmark in group:
            world.add_landmark(landmark)
        return group

    @staticmethod
    def _agent(name: str, spec: dict, adversary: bool, leader: bool) -> Agent:
        agent = Agent(
            name=name, collide=True, shape=Sphere(radius=spec["radius"]), u_multiplier=spec["u_multiplier"],
            max_speed=spec["max_speed"], color=spec["color"], adversary=adversary, silent=not leader,
        )
        agent.leader = leader
        return agent

    def reset_world_at(self, env_index=None) -> None:
        world = self.world
        rows = world.batch_dim if env_index is None else (1 if isinstance(env_index, int) else len(env_index))
        for entities, bound in ((world.agents, 1.0), (world.landmarks, 0.9)):
            for entity in entities:
                pos = torch.empty(rows, world.dim_p, device=world.device).uniform_(-bound, bound)
                entity.set_pos(pos.squeeze(0) if isinstance(env_index, int) else pos, batch_index=env_index)

    def reward(self, agent: Agent) -> torch.Tensor:
        if agent is self.world.agents[0]:
            prey = _stack(self.prey)
            food = _stack(self.food)
            caught = _touching(prey, self.prey_radius, _stack(self.predators), self.predator_radius)  # [B, G, A]
            eating = _touching(prey, self.prey_radius, food, self.food_radius)  # [B, G, F]
            nearest_food = torch.linalg.vector_norm(prey.unsqueeze(2) - food.unsqueeze(1), dim=-1).amin(dim=-1)
            prey_reward = FOOD_REWARD * eating.sum(dim=-1) - CATCH_REWARD * caught.sum(dim=-1)
            prey_reward = prey_reward - FOOD_DISTANCE_WEIGHT * nearest_food
            predator_reward = CATCH_REWARD * caught.sum(dim=(1, 2)).float()
            self._reward_cache = {a: prey_reward[:, i] for i, a in enumerate(self.prey)}
            self._reward_cache.update({a: predator_reward for a in self.predators})
        return self._reward_cache[agent]

    def observation(self, agent: Agent) -> torch.Tensor:
        world = self.world
        batch, n_forests = world.batch_dim, len(self.forests)
        own_pos = agent.state.pos
        landmarks = (_stack(world.landmarks) - own_pos.unsqueeze(1)).flatten(1)
        others = self.others[self._index[agent]]
        if agent.leader:
            other_pos = _stack(world.agents)[:, others] - own_pos.unsqueeze(1)  # [B, n - 1, 2]
            other_vel = torch.where(self.is_prey[others].view(1, -1, 1), _stack(world.agents, "vel")[:, others], 0.0)
        else:
            other_pos = other_vel = own_pos.new_zeros(batch, len(others), 2)
        per_forest = lambda x: x.unsqueeze(2).expand(-1, -1, n_forests, -1).flatten(1)  # noqa: E731
        in_forest = own_pos.new_full((batch, n_forests), -1.0)
        parts = [agent.state.vel, own_pos, landmarks, per_forest(other_pos), per_forest(other_vel), in_forest]
        if agent.adversary:
            parts.append(self.leader.state.c)
        return torch.cat(parts, dim=-1)


class HeuristicPolicy(BaseHeuristicPolicy):
    """Prey graze, the leader spots a prey and calls it, predators converge on the call.

    Roles come from the observation alone: predators' observations are
    ``DIM_C`` wider than prey's, and only the leader sees the prey (non-zero
    relative positions). Prey go to their nearest food. The leader chases the
    prey nearest to it and says where that prey is and how it moves
    (``(x + 1) / 2, (y + 1) / 2, (vx / 1.3 + 1) / 2, (vy / 1.3 + 1) / 2``);
    the other predators decode the message and chase the called position,
    led by the prey's velocity. Everyone is repelled by obstacles they are
    about to touch. The observation layout depends on the scenario's kwargs:
    pass the same ones here (the defaults match the scenario's). Continuous
    actions only.
    """

    gain = 3.0
    damping = 1.0
    lead_time = 0.3
    avoid_margin = 0.15
    avoid_gain = 2.0

    def __init__(self, continuous_action: bool = True, **layout) -> None:
        super().__init__(continuous_action)
        if not continuous_action:
            raise ValueError("simple_world_comm's heuristic supports continuous actions only")
        unknown = sorted(set(layout) - set(DEFAULTS))
        if unknown:
            raise ValueError(f"unknown layout kwargs {unknown}; expected some of {sorted(DEFAULTS)}")
        self.layout = dict(DEFAULTS, **layout)
        _check_layout(self.layout)
        n_obstacles, n_food, n_forests = (self.layout[k] for k in ("num_landmarks", "num_food", "num_forests"))
        self.n_prey = self.layout["num_good_agents"]
        self.n_others = self.n_prey + self.layout["num_adversaries"] - 1
        block = 2 * self.n_others * n_forests
        # observation slices (see the scenario docstring)
        self.obstacles = slice(4, 4 + 2 * n_obstacles)
        self.food = slice(self.obstacles.stop, self.obstacles.stop + 2 * n_food)
        landmarks_end = 4 + 2 * (n_obstacles + n_food + n_forests)
        self.other_pos = slice(landmarks_end, landmarks_end + block)
        self.other_vel = slice(self.other_pos.stop, self.other_pos.stop + block)
        self.prey_width = self.other_vel.stop + n_forests

    def compute_action(self, observation: torch.Tensor, u_range: float) -> torch.Tensor:
        batch, width = observation.shape
        if width not in (self.prey_width, self.prey_width + DIM_C):
            raise ValueError(
                f"observation width {width} does not fit layout {self.layout} (expected {self.prey_width} "
                f"or {self.prey_width + DIM_C}); build HeuristicPolicy with the scenario's kwargs"
            )
        vel, pos = observation[:, 0:2], observation[:, 2:4]
        obstacles = observation[:, self.obstacles].view(batch, -1, 2)
        if width == self.prey_width:
            return self._steer(_nearest(observation[:, self.food].view(batch, -1, 2)), vel, obstacles, u_range)
        # the prey are the last others; their copies (one per forest) are equal, take the first
        prey_pos = observation[:, self.other_pos].view(batch, self.n_others, -1, 2)[:, -self.n_prey:, 0]
        prey_vel = observation[:, self.other_vel].view(batch, self.n_others, -1, 2)[:, -self.n_prey:, 0]
        if bool((prey_pos != 0).any()):  # only the leader sees the prey
            pick = prey_pos.norm(dim=-1).argmin(dim=1).view(-1, 1, 1).expand(-1, 1, 2)
            rel, prey_v = prey_pos.gather(1, pick).squeeze(1), prey_vel.gather(1, pick).squeeze(1)
            message = torch.cat([(pos + rel + 1) / 2, (prey_v / PREY["max_speed"] + 1) / 2], dim=-1).clamp(0.0, 1.0)
            return torch.cat([self._steer(rel + self.lead_time * prey_v, vel, obstacles, u_range), message], dim=-1)
        message = observation[:, width - DIM_C:]
        heard = message.abs().sum(dim=-1, keepdim=True) > 0
        called = 2 * message[:, :2] - 1 - pos
        called_vel = (2 * message[:, 2:] - 1) * PREY["max_speed"]
        target = torch.where(heard, called + self.lead_time * called_vel, 0.0)
        return self._steer(target, vel, obstacles, u_range)

    def _steer(self, target, vel, obstacles, u_range: float) -> torch.Tensor:
        """Damped pursuit of ``target`` (relative), pushed sideways and away from nearby obstacles."""
        action = self.gain * target - self.damping * vel
        if obstacles.shape[1]:
            dist = obstacles.norm(dim=-1, keepdim=True).clamp(min=1e-6)
            away = -obstacles / dist
            gap = dist - OBSTACLE["radius"] - PREDATOR["radius"]
            push = ((self.avoid_margin - gap) / self.avoid_margin).clamp(min=0.0)
            side = torch.stack([-away[..., 1], away[..., 0]], dim=-1)
            side = side * torch.sign((side * target.unsqueeze(1)).sum(dim=-1, keepdim=True) + 1e-9)
            action = action + self.avoid_gain * (push * (away + side)).sum(dim=1)
        return action.clamp(-u_range, u_range)
