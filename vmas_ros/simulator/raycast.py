"""Batched ray casting against spheres, boxes and segments (Lidar kernels).

A ray starts at ``origin [..., 2]`` and points along ``s = (cos angle, sin angle)``
with ``angle [...]``. Entity parameters are ``[..., 2]`` points and ``[...]``
scalars (lengths, radii and ``max_range`` may also be python floats). All inputs
broadcast, so ``origin [B, R, 1, 2]`` / ``angle [B, R, 1]`` against entity
parameters ``[B, 1, E, ...]`` yields distances ``[B, R, E]``.

Each kernel returns the distance along the ray to the first hit, or
``max_range`` where the ray misses. Hits farther than ``max_range`` are NOT
clamped (as in VMAS); the sensor clamps by taking a min with ``max_range``.
Misses are decided with masks and guarded denominators, so no NaN reaches the
result.
"""
from __future__ import annotations

import math
from typing import Union

import torch
from torch import Tensor

from vmas_ros.simulator.geometry import cross2, rotate

__all__ = ["ray_sphere", "ray_box", "ray_segment"]

Scalar = Union[Tensor, float]


def _as_tensor(x: Scalar, like: Tensor) -> Tensor:
    """Turn a python number (or tensor) into a tensor on ``like``'s device/dtype."""
    return torch.as_tensor(x, dtype=like.dtype, device=like.device)


def _direction(angle: Tensor) -> Tensor:
    """Unit ray direction ``[..., 2]``."""
    return torch.stack([torch.cos(angle), torch.sin(angle)], dim=-1)


def ray_sphere(
    origin: Tensor, angle: Scalar, center: Tensor, radius: Scalar, max_range: Scalar
) -> Tensor:
    """Distance from ``origin`` along the ray to a disc of ``radius`` at ``center``.

    The ray hits iff the centre lies strictly in front of the origin
    (``(center - origin) . s > 0``) and the infinite ray line passes strictly
    closer than ``radius`` to the centre. The distance is that of the entry
    point: ``along - sqrt(radius^2 - offset^2)``. Consequently an origin inside
    the disc with the centre in front yields a NEGATIVE distance (the entry point
    lies behind the origin), while an origin inside with the centre behind is a
    miss; both quirks are kept for parity with VMAS.
    """
    angle, radius = _as_tensor(angle, origin), _as_tensor(radius, origin)
    max_range = _as_tensor(max_range, origin)
    s = _direction(angle)
    to_center = center - origin
    along = (to_center * s).sum(-1)  # signed distance to the foot of the perpendicular
    foot = origin + along[..., None] * s
    offset = torch.linalg.vector_norm(center - foot, dim=-1)
    hit = (offset < radius) & (along > 0)
    half_chord_sq = radius**2 - offset**2
    half_chord = torch.sqrt(torch.where(hit, half_chord_sq, torch.ones_like(half_chord_sq)))
    return torch.where(hit, along - half_chord, max_range)


def ray_box(
    origin: Tensor,
    angle: Scalar,
    center: Tensor,
    rot: Scalar,
    length: Scalar,
    width: Scalar,
    max_range: Scalar,
) -> Tensor:
    """Distance along the ray to a box (slab test in the box frame).

    The ray is expressed in the box frame, where the box is the axis-aligned
    rectangle ``|x| <= length/2, |y| <= width/2``. Per axis the ray is inside the
    slab for ``t`` in ``[lo, hi]``; the box is hit iff ``t_far = min(hi) >=
    t_near = max(lo)`` and ``t_near > 0`` (so an origin inside the box sees no
    hit), and the distance is ``t_near``.

    A direction component that is exactly zero gives an unbounded slab interval
    when the origin is strictly inside the slab and an empty one otherwise,
    including exactly on a slab plane (a ray sliding along a side misses). This
    equals VMAS's ``+-inf`` / NaN division outcome, without producing NaN.
    """
    angle, rot = _as_tensor(angle, origin), _as_tensor(rot, origin)
    length, width = _as_tensor(length, origin), _as_tensor(width, origin)
    max_range = _as_tensor(max_range, origin)

    local_origin = rotate(origin - center, -rot)
    local_dir = rotate(_direction(angle), -rot)
    half = torch.stack(torch.broadcast_tensors(length / 2, width / 2), dim=-1)

    flat = local_dir == 0
    dir_safe = torch.where(flat, torch.ones_like(local_dir), local_dir)
    t_a = (-half - local_origin) / dir_safe
    t_b = (half - local_origin) / dir_safe
    lo, hi = torch.minimum(t_a, t_b), torch.maximum(t_a, t_b)
    inside = local_origin.abs() < half
    inf = torch.full_like(lo, math.inf)
    lo = torch.where(flat, torch.where(inside, -inf, inf), lo)
    hi = torch.where(flat, torch.where(inside, inf, -inf), hi)

    t_near = lo.amax(dim=-1)
    t_far = hi.amin(dim=-1)
    hit = (t_far >= t_near) & (t_near > 0)
    return torch.where(hit, t_near, max_range)


def ray_segment(
    origin: Tensor,
    angle: Scalar,
    center: Tensor,
    rot: Scalar,
    length: Scalar,
    max_range: Scalar,
) -> Tensor:
    """Distance along the ray to a segment (``Line`` entity).

    Solves ``center + t * r = origin + u * s`` with ``r = d * length``: the
    segment is hit iff ``-0.5 <= t <= 0.5`` (endpoints count) and ``u >= 0``; the
    distance is ``u``. A ray parallel to the segment (also collinear) misses.
    """
    angle, rot = _as_tensor(angle, origin), _as_tensor(rot, origin)
    length, max_range = _as_tensor(length, origin), _as_tensor(max_range, origin)
    s = _direction(angle)
    r = _direction(rot) * length[..., None]
    w = origin - center
    rxs = cross2(r, s)
    parallel = rxs == 0
    rxs_safe = torch.where(parallel, torch.ones_like(rxs), rxs)
    t = cross2(w, s) / rxs_safe  # position on the segment, in units of its length
    u = cross2(w, r) / rxs_safe  # distance along the ray
    hit = ~parallel & (t >= -0.5) & (t <= 0.5) & (u >= 0)
    return torch.where(hit, u, max_range)
