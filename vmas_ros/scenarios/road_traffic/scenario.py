"""The ``road_traffic`` Scenario (see the package docstring for the task)."""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import read_kwargs
from vmas_ros.scenarios.road_traffic import geometry as geo
from vmas_ros.scenarios.road_traffic import map_data
from vmas_ros.scenarios.road_traffic.config import DEFAULTS, resolve
from vmas_ros.scenarios.road_traffic.observations import observe_all
from vmas_ros.simulator.core import Agent, Box, World
from vmas_ros.simulator.dynamics.kinematic_bicycle import KinematicBicycle
from vmas_ros.simulator.scenario import BaseScenario

#: per-agent penalties and rewards VMAS fixes (already divided by 100)
PENALTY_DEVIATE, PENALTY_NEAR_BOUNDARY, PENALTY_NEAR_AGENT = -0.02, -0.2, -0.2
PENALTY_COLLISION, PENALTY_STEERING, TIME_REWARD = -1.0, -0.02, 0.05
#: agents start at least this factor times their diagonal apart
SPAWN_CLEARANCE = 1.2


def _color(i: int) -> tuple:
    """A fixed, well-spread colour per agent (golden-ratio hue steps)."""
    hue = (i * 0.618034) % 1.0
    return tuple(0.5 + 0.4 * math.cos(2 * math.pi * (hue - shift)) for shift in (0.0, 1 / 3, 2 / 3))


class Scenario(BaseScenario):
    supports_batched_reset = True

    def make_world(self, batch_dim: int, device, **kwargs) -> World:
        config = resolve(read_kwargs(kwargs, DEFAULTS))
        if not config["is_partial_observation"] and not config["is_ego_view"]:
            raise ValueError(
                "road_traffic: is_partial_observation=False needs is_ego_view=True "
                "(VMAS's full bird-view layout cannot be built)"
            )
        for name, value in config.items():
            setattr(self, name, value)
        self.visualize_semidims = False
        n_look = self.n_points_short_term * self.sample_interval_ref_path
        self.routes, self.mean_lane_width = map_data.load(self.map_file_path, n_look, device)
        self.steering_threshold = math.radians(self.threshold_change_steering)
        self.spawn_distance = math.sqrt((self.l_f + self.l_r) ** 2 + self.agent_width**2) * SPAWN_CLEARANCE
        world = World(batch_dim, device, x_semidim=self.world_x_dim, y_semidim=self.world_y_dim, dt=self.dt)
        for i in range(self.n_agents):
            world.add_agent(Agent(
                name=f"agent_{i}", shape=Box(length=self.l_f + self.l_r, width=self.agent_width), color=_color(i),
                collide=False, render_action=False, u_range=[self.max_speed, self.max_steering_angle],
                u_multiplier=[1, 1], max_speed=self.max_speed,
                dynamics=KinematicBicycle(world, width=self.agent_width, l_f=self.l_f, l_r=self.l_r,
                                          max_steering_angle=self.max_steering_angle, integration="rk4"),
            ))
        ego = self.is_ego_view
        scale = [self.agent_length * 10] * 2 if ego else [self.world_x_dim, self.world_y_dim]
        self.pos_scale = torch.tensor(scale, device=device)
        weights = torch.linspace(1, 0.2, self.n_points_short_term, device=device)
        self.look_weights = weights / weights.sum()  # nearer look-ahead points weigh more in the progress reward
        self._allocate(batch_dim, world.device)
        return world

    def _allocate(self, batch: int, device) -> None:
        """Per-env state; every tensor [B, n, ...] over envs and agents."""
        n, P = self.n_agents, self.routes.centre.shape[1]
        zeros = lambda *shape, dtype=torch.float32: torch.zeros(batch, n, *shape, device=device, dtype=dtype)  # noqa: E731
        self.route_id, self.start_point = zeros(dtype=torch.long), zeros(dtype=torch.long)
        self.centre, self.left, self.right = zeros(P, 2), zeros(P, 2), zeros(P, 2)
        self.n_centre, self.n_left, self.n_right = zeros(dtype=torch.long), zeros(dtype=torch.long), zeros(dtype=torch.long)
        self.is_loop = zeros(dtype=torch.bool)
        self.entry, self.exit = zeros(2, 2), zeros(2, 2)
        self.prev_pos = zeros(2)  # positions when the rewards were last given
        self.short_term = zeros(self.n_points_short_term, 2)
        self.near_left = zeros(self.n_points_nearing_boundary, 2)
        self.near_right = zeros(self.n_points_nearing_boundary, 2)
        self.vertices = zeros(5, 2)
        self.dist_ref, self.dist_boundary = zeros(), zeros()
        self.dist_left, self.dist_right = zeros(5), zeros(5)  # centre (minus half the width), then the 4 corners
        self.nearest_ref = zeros(dtype=torch.long)
        self.nearest_left, self.nearest_right = zeros(dtype=torch.long), zeros(dtype=torch.long)
        self.mutual = zeros(n)
        self.hit_agents = zeros(n, dtype=torch.bool)
        self.hit_boundary, self.hit_entry, self.hit_exit = zeros(dtype=torch.bool), zeros(dtype=torch.bool), zeros(dtype=torch.bool)
        # the steering commands of the last two observations (``_observed`` of them so far, in all envs)
        self.steer_last, self.steer_before = zeros(), zeros()
        self._observed = 0
        #: [B] envs reset since the last observation (with reset_steering_history): they record no steering
        self._history_cleared = torch.zeros(batch, dtype=torch.bool, device=device)
        self._rewards = zeros()
        self._obs = None

    # ------------------------------------------------------------------- reset
    def _rows(self, env_index) -> Tensor:
        device, batch = self.world.device, self.world.batch_dim
        if env_index is None:
            return torch.arange(batch, device=device)
        if isinstance(env_index, int):
            return torch.tensor([env_index], device=device)
        return torch.as_tensor(env_index, device=device).reshape(-1)

    def _draw_starts(self, rows: Tensor):
        """Route, start point, position for every agent of ``rows``; agents keep their distance."""
        device, count = self.world.device, len(rows)
        routes, n_routes = self.routes, self.routes.centre.shape[0]
        route = torch.zeros(count, self.n_agents, dtype=torch.long, device=device)
        point = torch.zeros_like(route)
        pos = torch.zeros(count, self.n_agents, 2, device=device)
        probabilities = self.scenario_probabilities
        intersection_only = probabilities[1] == 0 and probabilities[2] == 0
        for i in range(self.n_agents):  # each agent keeps clear of the ones placed before it
            todo = torch.ones(count, dtype=torch.bool, device=device)
            while True:
                r = torch.randint(0, n_routes, (count,), device=device)
                n_points = routes.n_centre[r]
                low, high = (6, n_points // 2) if intersection_only else (3, n_points - 5)
                p = low + (torch.rand(count, device=device) * (high - low)).long()
                candidate = routes.centre[r, p]
                route[:, i] = torch.where(todo, r, route[:, i])
                point[:, i] = torch.where(todo, p, point[:, i])
                pos[:, i] = torch.where(todo.unsqueeze(-1), candidate, pos[:, i])
                if i == 0:
                    break
                gap = torch.linalg.vector_norm(pos[:, :i] - pos[:, i : i + 1], dim=-1).min(dim=1)[0]
                todo = gap < self.spawn_distance
                if not todo.any():  # a reset may sync: draws repeat until every env is clear
                    break
        return route, point, pos

    def reset_world_at(self, env_index=None) -> None:
        rows = self._rows(env_index)
        route, point, pos = self._draw_starts(rows)
        rot = self.routes.yaw[route, point]
        speed = torch.rand(len(rows), self.n_agents, device=self.world.device) * self.max_speed
        vel = speed.unsqueeze(-1) * torch.stack([torch.cos(rot), torch.sin(rot)], dim=-1)
        self.set_starts(rows, route, point, pos, rot, vel)

    def set_starts(self, rows: Tensor, route: Tensor, point: Tensor, pos: Tensor, rot: Tensor, vel: Tensor) -> None:
        """Put the agents of envs ``rows`` on routes ``route`` [R, n] at the given states, and
        recompute what depends on them (as a reset does)."""
        for i, agent in enumerate(self.world.agents):
            agent.set_pos(pos[:, i].clone(), batch_index=rows)
            agent.set_rot(rot[:, i : i + 1].clone(), batch_index=rows)
            agent.set_vel(vel[:, i].clone(), batch_index=rows)
        r = self.routes
        self.route_id[rows], self.start_point[rows] = route, point
        for name in ("centre", "left", "right", "n_centre", "n_left", "n_right", "is_loop", "entry", "exit"):
            getattr(self, name)[rows] = getattr(r, name)[route]
        self._track(rows)
        self._look_ahead(rows, shift=1)
        mutual = self._mutual_distances()
        self.mutual[rows] = mutual[rows]
        for name in ("hit_agents", "hit_boundary", "hit_entry", "hit_exit"):
            getattr(self, name)[rows] = False
        self.prev_pos[rows] = self._stack("pos")[rows]
        if self.reset_steering_history:  # the episode starts without the last one's steering
            self.steer_last[rows] = 0
            self.steer_before[rows] = 0
            self._history_cleared[rows] = True

    # --------------------------------------------------------------- tracking
    def _stack(self, field: str) -> Tensor:
        return torch.stack([getattr(a.state, field) for a in self.world.agents], dim=1)

    def _mutual_distances(self) -> Tensor:
        """Centre distances [B, n, n]; an agent's own is larger than every other in its env (the env's
        largest + 1; VMAS takes the whole batch's largest, which couples the envs)."""
        pos = self._stack("pos")
        mutual = torch.linalg.vector_norm(pos.unsqueeze(2) - pos.unsqueeze(1), dim=-1)
        eye = torch.eye(self.n_agents, dtype=torch.bool, device=pos.device)
        return torch.where(eye, mutual.amax(dim=(1, 2), keepdim=True) + 1, mutual)

    def _track(self, rows) -> None:
        """Corners and distances to route and boundaries (with the nearest points) for envs ``rows``."""
        pos, rot = self._stack("pos")[rows], self._stack("rot")[rows][..., 0]
        corners = geo.rectangle(pos, rot, self.l_f + self.l_r, self.agent_width)  # [R, n, 5, 2]
        self.vertices[rows] = corners
        queries = torch.cat([pos.unsqueeze(2), corners[:, :, :4]], dim=2)  # [R, n, 5, 2]
        self.dist_ref[rows], self.nearest_ref[rows] = (
            v[..., 0] for v in geo.polyline_distance(pos.unsqueeze(2), self.centre[rows], self.n_centre[rows])
        )
        half = self.agent_width / 2
        for side, dist, nearest, count in (
            (self.left, self.dist_left, self.nearest_left, self.n_left),
            (self.right, self.dist_right, self.nearest_right, self.n_right),
        ):
            d, index = geo.polyline_distance(queries, side[rows], count[rows])
            d[..., 0] = d[..., 0] - half
            dist[rows], nearest[rows] = d, index[..., 0]
        self.dist_boundary[rows] = torch.cat([self.dist_left[rows], self.dist_right[rows]], dim=-1).min(dim=-1)[0]

    def _look_ahead(self, rows, shift: int) -> None:
        """Look-ahead points on the route and, if observed, on the boundaries, for envs ``rows``.

        After a reset the boundary points start just ahead of the nearest one,
        during an episode two points behind it (VMAS's choice, kept).
        """
        n_centre, loop = self.n_centre[rows], self.is_loop[rows]
        self.short_term[rows] = geo.look_ahead(
            self.centre[rows], self.nearest_ref[rows], n_centre, loop, self.n_points_short_term,
            self.sample_interval_ref_path, 1,
        )
        if not self.is_observe_distance_to_boundaries:
            for side, nearest, out in ((self.left, self.nearest_left, self.near_left),
                                       (self.right, self.nearest_right, self.near_right)):
                out[rows] = geo.look_ahead(side[rows], nearest[rows], n_centre, loop,
                                           self.n_points_nearing_boundary, 1, shift)

    def _detect_collisions(self, previous: Tensor) -> None:
        """Corner polygons crossing each other, the route's boundaries, its entry or its exit.

        As in VMAS 1.5.2, agent i < j is tested against j's corners of the
        previous step (``previous`` [B, n, 5, 2]; VMAS refreshes j's corners only
        after testing the pair), and the result is recorded for both.
        """
        v = self.vertices
        hits = geo.crossing(v.unsqueeze(2), previous.unsqueeze(1))  # [B, i, j]
        upper = torch.ones(self.n_agents, self.n_agents, dtype=torch.bool, device=v.device).triu(1)
        hits = hits & upper
        self.hit_agents = hits | hits.transpose(1, 2)
        self.hit_boundary = geo.crossing(v, self.left) | geo.crossing(v, self.right)
        open_route = ~self.is_loop.any(dim=0)  # [n]: checked only where no env drives a loop
        self.hit_entry = geo.crossing(v, self.entry) & open_route
        self.hit_exit = geo.crossing(v, self.exit) & open_route

    # ------------------------------------------------------------------ reward
    def _all_rewards(self) -> Tensor:
        """Every agent's reward [B, n]; advances the per-step tracking state."""
        everyone = slice(None)
        self.mutual = self._mutual_distances()
        pos, vel = self._stack("pos"), self._stack("vel")
        previous = self.vertices.clone()
        self._track(everyone)
        self._detect_collisions(previous)
        max_step = self.max_speed * self.dt
        to_ref = self.short_term - self.prev_pos.unsqueeze(2)  # [B, n, k, 2] from last position to look-ahead
        progress = ((pos - self.prev_pos).unsqueeze(2) * to_ref).sum(-1) @ self.look_weights
        reward = progress / max_step * (self.reward_progress / 100)
        along = (vel.unsqueeze(2) * to_ref).sum(-1).mean(-1)  # [B, n]
        forward = along > 0
        reward = reward + torch.where(forward, 1.0, 2.0) * along / self.max_speed * (self.reward_vel / 100)
        reward = reward + self.hit_exit * (self.reward_reach_goal / 100)
        boundary_fade = geo.fading(self.dist_boundary, self.threshold_near_boundary_low, self.threshold_near_boundary_high)
        reward = reward + boundary_fade * PENALTY_NEAR_BOUNDARY
        agent_fade = geo.fading(
            self.mutual, self.threshold_near_other_agents_c2c_low, self.threshold_near_other_agents_c2c_high
        )
        reward = reward + agent_fade.sum(-1) * PENALTY_NEAR_AGENT
        reward = reward + self.dist_ref / (self.mean_lane_width / 2) * PENALTY_DEVIATE
        reward = reward + self._steering_penalty()
        reward = reward + self.hit_agents.any(-1) * PENALTY_COLLISION + self.hit_boundary * PENALTY_COLLISION
        speed = torch.linalg.vector_norm(vel, dim=-1)
        reward = reward + torch.where(forward, 1.0, -1.0) * speed / self.max_speed * TIME_REWARD
        self._look_ahead(everyone, shift=-2)
        self.prev_pos = pos
        return reward

    def _steering_penalty(self) -> Tensor:
        """Penalty on the change between the last two observed steering commands beyond a threshold."""
        before = self.steer_before if (self._observed >= 2 and self.n_stored_steps >= 2) else self.steer_last
        change = ((self.steer_last - before).abs() * self.max_steering_angle - self.steering_threshold).clamp(min=0)
        return change / (2 * self.max_steering_angle - 2 * self.steering_threshold) * PENALTY_STEERING

    def reward(self, agent: Agent) -> Tensor:
        index = self.world.agents.index(agent)
        if index == 0:
            self._rewards = self._all_rewards()
        return self._rewards[:, index]

    # ------------------------------------------------------------- observation
    def _record_steering(self) -> None:
        agents = self.world.agents
        if agents[0].action.u is None:
            steer = torch.zeros_like(self.steer_last)
        else:
            steer = torch.stack([a.action.u[:, 1] for a in agents], dim=1) / self.max_steering_angle
        if self.reset_steering_history:  # an env reset since: its agents' actions are the last episode's
            steer = steer.masked_fill(self._history_cleared.unsqueeze(1), 0.0)
            self._history_cleared.zero_()
        self.steer_before, self.steer_last = self.steer_last, steer
        self._observed += 1

    def observation(self, agent: Agent) -> Tensor:
        index = self.world.agents.index(agent)
        if index == 0 or self._obs is None:
            self._obs = observe_all(self)
            self._record_steering()
        obs = self._obs[:, index]
        if self.is_add_noise:
            obs = obs + self.noise_level * torch.rand_like(obs)
        return obs

    def info(self, agent: Agent) -> dict:
        index = self.world.agents.index(agent)
        u = agent.action.u
        wrapped = torch.remainder(agent.state.rot, 2 * math.pi)
        wrapped = torch.where(wrapped > math.pi, wrapped - 2 * math.pi, wrapped)
        no_action = torch.zeros(self.world.batch_dim, device=self.world.device)
        world_size = torch.tensor([self.world_x_dim, self.world_y_dim], device=self.world.device)
        lane = self.lane_width * 3
        return {
            "pos": agent.state.pos / world_size,
            "rot": wrapped / (2 * math.pi),
            "vel": agent.state.vel / self.max_speed,
            "act_vel": u[:, 0] / self.max_speed if u is not None else no_action,
            "act_steer": u[:, 1] / self.max_steering_angle if u is not None else no_action,
            "ref": (self.short_term[:, index] / world_size).flatten(1),
            "distance_ref": self.dist_ref[:, index] / lane,
            "distance_left_b": self.dist_left[:, index].min(dim=-1)[0] / lane,
            "distance_right_b": self.dist_right[:, index].min(dim=-1)[0] / lane,
            "is_collision_with_agents": self.hit_agents[:, index].any(dim=-1),
            "is_collision_with_lanelets": self.hit_boundary.any(dim=-1),
        }

    def done(self) -> Tensor:
        return self.hit_agents.flatten(1).any(dim=-1) | self.hit_boundary.any(dim=-1)
