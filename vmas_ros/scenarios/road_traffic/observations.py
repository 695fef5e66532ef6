"""Observations of ``road_traffic``: every agent's vector, built for all agents at once.

:func:`observe_all` returns ``[B, n_agents, obs size]``; the scenario calls it
once per step (for the first agent) and hands each agent its row. The layout
(per agent, in order) is described in the package docstring.
"""
from __future__ import annotations

import math
from typing import List

import torch
from torch import Tensor

from vmas_ros.scenarios.road_traffic import geometry as geo


def _to_frames(points: Tensor, pos: Tensor, rot: Tensor) -> Tensor:
    """Points of every agent j seen from every agent i: [B, n, ..., 2] -> [B, n (i), n (j), ..., 2]."""
    extra = points.dim() - 3  # point dims between the agent dim and the xy dim
    shape = (pos.shape[0], pos.shape[1], 1) + (1,) * extra
    return geo.to_local(points.unsqueeze(1), pos.view(*shape, 2), rot.view(*shape))


def _others(s, features: List[Tensor], picked: Tensor) -> Tensor:
    """Concatenate per-other features as VMAS lays them out: [B, n, k * features].

    Each feature is ``[B, n (observer), m (others), ...]``; it is regrouped into
    ``k = n_nearing_agents_observed`` blocks before the features are joined, so
    the layout is VMAS's for ``m == k`` (partial observation, where each block is
    one neighbour) and for ``m == n_agents`` (full observation) alike.
    """
    batch, n, k = picked.shape[0], picked.shape[1], s.n_nearing_agents_observed
    blocks = [f.reshape(batch, n, k, -1) for f in features]
    return torch.cat(blocks, dim=-1).reshape(batch, n, -1)


def observe_all(s) -> Tensor:
    """Every agent's observation without noise, [B, n, obs size] (``s`` is the Scenario)."""
    agents = s.world.agents
    pos = torch.stack([a.state.pos for a in agents], dim=1)  # [B, n, 2]
    rot = torch.stack([a.state.rot[:, 0] for a in agents], dim=1)  # [B, n]
    vel = torch.stack([a.state.vel for a in agents], dim=1)
    batch, n = rot.shape
    ego = s.is_ego_view
    scale = s.pos_scale  # [2]: agent-length based (ego view) or world size (bird view)
    corners = s.vertices[:, :, :4]
    if ego:
        heading = rot.unsqueeze(1) - rot.unsqueeze(2)  # [B, i, j]
        speed = torch.linalg.vector_norm(vel, dim=-1).unsqueeze(1)  # [B, 1, j]
        other_pos = _to_frames(pos, pos, rot) / scale
        other_rot = heading / (2 * math.pi)
        other_vel = torch.stack([speed * torch.cos(heading), speed * torch.sin(heading)], dim=-1) / s.max_speed
        other_ref = _to_frames(s.short_term, pos, rot) / scale
        other_corners = _to_frames(corners, pos, rot) / scale
        eye = torch.arange(n, device=pos.device)
        own = [other_vel[:, eye, eye, :1], other_ref[:, eye, eye].flatten(2)]
    else:
        other_pos, other_rot = pos / scale, rot / (2 * math.pi)
        other_vel, other_ref, other_corners = vel / s.max_speed, s.short_term / scale, corners / scale
        own = [other_pos, other_rot.unsqueeze(-1), other_vel, other_ref.flatten(2)]
    lane = s.lane_width * 3  # distance normaliser
    if s.is_observe_distance_to_center_line:
        own.append((s.dist_ref / lane).unsqueeze(-1))
    if s.is_observe_distance_to_boundaries:
        own += [(s.dist_left.min(dim=-1)[0] / lane).unsqueeze(-1), (s.dist_right.min(dim=-1)[0] / lane).unsqueeze(-1)]
    else:
        for side in (s.near_left, s.near_right):
            points = geo.to_local(side, pos.unsqueeze(-2), rot.unsqueeze(-1)) if ego else side
            own.append((points / scale).flatten(2))

    distance = s.mutual / lane  # [B, i, j]
    if s.is_partial_observation:
        nearest, picked = torch.topk(s.mutual, s.n_nearing_agents_observed, dim=-1, largest=False)  # [B, n, k]
        far = nearest >= s.agent_length * 10 if s.is_apply_mask else torch.zeros_like(nearest, dtype=torch.bool)

        def pick(feature: Tensor, masked_value: float) -> Tensor:
            if ego:  # [B, i, j, ...]
                index = picked.view(*picked.shape, *([1] * (feature.dim() - 3)))
                chosen = feature.gather(2, index.expand(*picked.shape, *feature.shape[3:]))
            else:  # [B, j, ...], the same for every observer
                rows = torch.arange(batch, device=feature.device).view(batch, 1, 1)
                chosen = feature[rows, picked]
            mask = far.view(*far.shape, *([1] * (chosen.dim() - 3)))
            return torch.where(mask, masked_value, chosen)

        picked_distance = torch.where(far, 1.0, distance.gather(2, picked))
    else:  # full observation (ego view only): every agent, the observer's own distance zeroed
        picked = torch.zeros(batch, n, n, dtype=torch.long, device=pos.device)

        def pick(feature: Tensor, masked_value: float) -> Tensor:
            return feature

        picked_distance = distance * (1 - torch.eye(n, device=pos.device))
    features = [pick(other_corners, 1.0).flatten(3)] if s.is_observe_vertices else [
        pick(other_pos, 1.0), pick(other_rot.unsqueeze(-1), 0.0)
    ]
    features.append(pick(other_vel, 0.0))
    if s.is_observe_distance_to_agents:
        features.append(picked_distance.unsqueeze(-1))
    if s.is_observe_ref_path_other_agents:
        features.append(pick(other_ref, 1.0).flatten(3))
    return torch.cat([*own, _others(s, features, picked)], dim=-1)
