"""A lane-following baseline for ``road_traffic``: pure pursuit on the observed route, braking for traffic."""
from __future__ import annotations

import math

import torch
from torch import Tensor

from vmas_ros.scenarios.common import heuristic_kwargs
from vmas_ros.scenarios.road_traffic.config import DEFAULTS, resolve
from vmas_ros.scenarios.road_traffic.geometry import to_local
from vmas_ros.simulator.heuristic_policy import BaseHeuristicPolicy


class HeuristicPolicy(BaseHeuristicPolicy):
    """Steer for a look-ahead point of the own route; slow down behind other vehicles.

    Reads only the agent's observation (the layout follows from the scenario
    kwargs, which must be those the env was built with):

    * the look-ahead points of the own route (ego frame, or turned into it
      from the bird view using the observed own pose) give the aim point, the
      mean of the first two; pure pursuit turns it into a steering angle
      ``atan(2 * wheelbase * sin(alpha) / distance)``;
    * speed is ``cruise`` x max speed, scaled down on sharp bends, and zero
      while a corner of an observed neighbour lies in the ``brake_box`` ahead
      (partial observation with vertices only; otherwise no braking).
    """

    cruise = 0.6
    brake_ahead = (0.02, 0.42)  # [m] ahead of the centre, where a neighbour's corner makes us stop
    brake_half_width = 0.11  # [m] either side

    def __init__(self, continuous_action: bool = True, **scenario_kwargs) -> None:
        super().__init__(continuous_action)
        cfg = resolve(heuristic_kwargs("road_traffic", DEFAULTS, scenario_kwargs))
        self.cfg = cfg
        self.ego = cfg["is_ego_view"]
        k = cfg["n_points_short_term"]
        boundary = 1 if cfg["is_observe_distance_to_boundaries"] else 2 * cfg["n_points_nearing_boundary"]
        self.ref_start = 1 if self.ego else 5
        self.ref_size = 2 * k
        own = self.ref_start + self.ref_size + int(cfg["is_observe_distance_to_center_line"]) + 2 * boundary
        self.own_size = own
        per_other = (8 if cfg["is_observe_vertices"] else 3) + 2 + int(cfg["is_observe_distance_to_agents"])
        per_other += 2 * k if cfg["is_observe_ref_path_other_agents"] else 0
        self.per_other = per_other
        n_others = cfg["n_nearing_agents_observed"] if cfg["is_partial_observation"] else cfg["n_agents"]
        self.width = own + per_other * n_others
        self.brakes = cfg["is_partial_observation"] and cfg["is_observe_vertices"]
        self.n_others = cfg["n_nearing_agents_observed"]
        self.scale = cfg["agent_length"] * 10 if self.ego else None
        self.wheelbase = cfg["l_f"] + cfg["l_r"]

    def _frame(self, observation: Tensor):
        """Own position [b, 2] and heading [b] in the frame the observation uses, and its length scale [2]."""
        b, device = observation.shape[0], observation.device
        if self.ego:
            scale = torch.full((2,), float(self.scale), device=device)
            return torch.zeros(b, 2, device=device), torch.zeros(b, device=device), scale
        scale = torch.tensor([self.cfg["world_x_dim"], self.cfg["world_y_dim"]], device=device)
        return observation[:, 0:2] * scale, observation[:, 2] * 2 * math.pi, scale

    def compute_action(self, observation: Tensor, u_range) -> Tensor:
        if observation.shape[1] != self.width:
            raise ValueError(f"road_traffic heuristic: expected observation width {self.width}, got {observation.shape[1]}")
        pos, rot, scale = self._frame(observation)
        ref = observation[:, self.ref_start : self.ref_start + self.ref_size].reshape(-1, self.ref_size // 2, 2) * scale
        ref = to_local(ref, pos.unsqueeze(1), rot.unsqueeze(1))  # [b, k, 2] in the own frame [m]
        aim = ref[:, : min(2, ref.shape[1])].mean(dim=1)
        alpha = torch.atan2(aim[:, 1], aim[:, 0])
        distance = torch.linalg.vector_norm(aim, dim=-1).clamp(min=1e-3)
        max_steer = float(self.cfg["max_steering_angle"])
        steer = torch.atan(2 * self.wheelbase * torch.sin(alpha) / distance).clamp(-max_steer, max_steer)
        speed = self.cruise * self.cfg["max_speed"] * (1 - 0.5 * (steer.abs() / max_steer))
        if self.brakes:
            others = observation[:, self.own_size :].reshape(-1, self.n_others, self.per_other)[..., :8]
            corners = to_local(others.reshape(-1, self.n_others * 4, 2) * scale, pos.unsqueeze(1), rot.unsqueeze(1))
            x, y = corners[..., 0], corners[..., 1]
            blocked = ((x > self.brake_ahead[0]) & (x < self.brake_ahead[1]) & (y.abs() < self.brake_half_width)).any(-1)
            speed = torch.where(blocked, 0.0, speed)
        return torch.stack([speed, steer], dim=-1)
