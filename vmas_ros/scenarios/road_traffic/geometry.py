"""Batched polyline geometry for ``road_traffic``: distances, look-ahead points, crossings, frames.

Every function works on leading batch dimensions ``...`` (envs, agents, ...)
so that the scenario treats all envs and all agents in one call.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

#: squared-length guard of a segment projection (zero-length padding segments)
EPS = 1e-8


def polyline_distance(points: Tensor, polyline: Tensor, n_points: Tensor):
    """Distance from each point to a polyline and the index just past its nearest segment.

    Args:
        points: [..., Q, 2] query points (Q per polyline).
        polyline: [..., P, 2] padded polylines.
        n_points: [...] long, real points of each polyline; segments from index
            ``n_points - 1`` on (padding) count as the last real segment.
    Returns:
        ([..., Q] distances, [..., Q] long index of the nearest segment's end
        point, so that the point it names lies ahead of the query point).
    """
    start, seg = polyline[..., :-1, :], polyline.diff(dim=-2)  # [..., P-1, 2]
    rel = points.unsqueeze(-2) - start.unsqueeze(-3)  # [..., Q, P-1, 2]
    along = (rel * seg.unsqueeze(-3)).sum(-1) / ((seg * seg).sum(-1) + EPS).unsqueeze(-2)
    nearest = start.unsqueeze(-3) + seg.unsqueeze(-3) * along.clamp(0, 1).unsqueeze(-1)
    gap = torch.linalg.vector_norm(nearest - points.unsqueeze(-2), dim=-1)  # [..., Q, P-1]
    segment = torch.arange(gap.shape[-1], device=gap.device)
    last = (n_points - 2).unsqueeze(-1).unsqueeze(-1)  # [..., 1, 1]
    gap = torch.where(segment >= last + 1, gap.gather(-1, last.expand(*gap.shape[:-1], 1)), gap)
    distance, index = gap.min(dim=-1)
    return distance, index + 1


def look_ahead(polyline: Tensor, nearest: Tensor, n_points: Tensor, is_loop: Tensor, count: int,
               interval: int, shift: int) -> Tensor:
    """``count`` points of a polyline every ``interval`` from ``nearest + shift``: [..., count, 2].

    Args:
        polyline: [..., P, 2]; nearest, n_points: [...] long; is_loop: [...] bool.
    On a closed loop (whose last point repeats its first) indices that reach
    the last point wrap around, skipping the repeated point.
    """
    index = nearest.unsqueeze(-1) + shift + interval * torch.arange(count, device=polyline.device)
    n = n_points.unsqueeze(-1)
    wrapped = torch.where(index >= n - 1, torch.remainder(index + 1, n), index)
    index = torch.where(is_loop.unsqueeze(-1), wrapped, index)
    return polyline.gather(-2, index.unsqueeze(-1).expand(*index.shape, 2))


def crossing(a: Tensor, b: Tensor) -> Tensor:
    """Whether polylines ``a`` [..., A, 2] and ``b`` [..., B, 2] cross: [...] bool.

    Two segments cross when each one's end points lie strictly on opposite
    sides of the other's line; touching or collinear segments (and the
    zero-length segments of padding) do not count.
    """
    a0, da = a[..., :-1, :].unsqueeze(-2), a.diff(dim=-2).unsqueeze(-2)  # [..., A-1, 1, 2]
    b0, db = b[..., :-1, :].unsqueeze(-3), b.diff(dim=-2).unsqueeze(-3)  # [..., 1, B-1, 2]
    b1 = b0 + db
    a1 = a0 + da

    def side(origin, direction, point):
        rel = point - origin
        return direction[..., 0] * rel[..., 1] - direction[..., 1] * rel[..., 0]

    b_apart = side(a0, da, b0) * side(a0, da, b1) < 0
    a_apart = side(b0, db, a0) * side(b0, db, a1) < 0
    return (a_apart & b_apart).flatten(-2).any(dim=-1)


def rectangle(centre: Tensor, yaw: Tensor, length: float, width: float) -> Tensor:
    """Corners of rectangles, closed (the first repeated last): [..., 5, 2].

    Order: front-left, front-right, rear-right, rear-left, front-left, with
    ``centre`` [..., 2] and ``yaw`` [...] the heading of the long side.
    """
    half = torch.tensor(
        [[1, 1], [1, -1], [-1, -1], [-1, 1], [1, 1]], dtype=centre.dtype, device=centre.device
    ) * torch.tensor([length / 2, width / 2], dtype=centre.dtype, device=centre.device)
    return to_world(half, centre.unsqueeze(-2), yaw.unsqueeze(-1))


def to_world(local: Tensor, origin: Tensor, yaw: Tensor) -> Tensor:
    """Points given in a frame at ``origin`` turned by ``yaw`` into world coordinates."""
    cos, sin = torch.cos(yaw), torch.sin(yaw)
    x, y = local[..., 0], local[..., 1]
    return torch.stack([cos * x - sin * y, sin * x + cos * y], dim=-1) + origin


def to_local(points: Tensor, origin: Tensor, yaw: Tensor) -> Tensor:
    """World points in the frame at ``origin`` [..., 2] heading ``yaw`` [...] (broadcast by the caller)."""
    rel = points - origin
    cos, sin = torch.cos(yaw), torch.sin(yaw)
    x, y = rel[..., 0], rel[..., 1]
    return torch.stack([cos * x + sin * y, -sin * x + cos * y], dim=-1)


def fading(x: Tensor, near: float, far: float) -> Tensor:
    """1 at ``x <= near`` falling exponentially to 0 at ``x >= far`` (a proximity penalty weight)."""
    t = (x.clamp(min=near, max=far) - near) / (far - near)
    return (torch.exp(-t) - math.exp(-1)) / (1 - math.exp(-1))
