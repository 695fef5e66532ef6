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

The work is done by the ``*_xy`` kernels, which take x and y components as
separate tensors (structure of arrays): the Lidar lays rays out as
``[E, B, R]`` (targets, envs, rays) so that each op runs over one contiguous
block and the nearest hit is a reduction over the leading dim. ``[..., 2]``
vectors made every op stride over pairs of floats and every dot product a slow
reduction over a trailing dim of two. The ``[..., 2]`` functions are thin
adapters over them.
"""
from __future__ import annotations

import math
from typing import Optional, Tuple, Union

import torch
from torch import Tensor

from vmas_ros.simulator.masks import mask_gt, mask_lt


__all__ = ["ray_sphere", "ray_box", "ray_segment", "ray_sphere_xy", "ray_box_xy", "ray_segment_xy",
           "ray_sphere_nearest_xy", "ray_sphere_reach_xy"]

Scalar = Union[Tensor, float]


def _as_tensor(x: Scalar, like: Tensor) -> Tensor:
    """Turn a python number (or tensor) into a tensor on ``like``'s device/dtype."""
    return torch.as_tensor(x, dtype=like.dtype, device=like.device)


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
    angle = _as_tensor(angle, origin)
    return ray_sphere_xy(
        origin[..., 0], origin[..., 1], torch.cos(angle), torch.sin(angle),
        center[..., 0], center[..., 1], _as_tensor(radius, origin), _as_tensor(max_range, origin),
    )


def ray_sphere_xy(
    ox: Tensor, oy: Tensor, cos_a: Tensor, sin_a: Tensor, cx: Tensor, cy: Tensor, radius: Scalar, max_range: Scalar,
) -> Tensor:
    """:func:`ray_sphere` on separate x/y components (origin, ray direction, centre); all broadcast.

    Laid out for the LIDAR, where the centre offset is per target and env
    (``[E, B, 1]``) and the direction per ray (``[1, B, R]``), so the fewer
    passes over ``[E, B, R]`` the better (ten here):

    * ``along``, the signed distance to the foot of the perpendicular, is the
      only per-ray product;
    * the squared half chord ``r^2 - across^2`` is ``along^2 - (|c|^2 - r^2)``,
      whose second term is per target and env;
    * hit (``half chord^2 > 0`` and ``along > 0``) is one float mask
      (``torch.where`` is far slower than arithmetic on the CPU).

    A miss returns exactly ``max_range``; a hit may differ from the textbook
    formula in the last bits. The root's argument is clamped to a tiny
    positive value, so misses get neither NaN values nor NaN gradients.
    """
    to_cx, to_cy = cx - ox, cy - oy
    along = torch.addcmul(to_cx * cos_a, to_cy, sin_a)
    beyond_sq = torch.addcmul(to_cx * to_cx, to_cy, to_cy) - radius * radius  # |c|^2 - r^2, per target and env
    half_chord_sq = torch.addcmul(-beyond_sq, along, along)
    if not (torch.is_grad_enabled() and half_chord_sq.requires_grad):
        # the same arithmetic in place: three [E, B, R] temporaries instead of eight (each fresh
        # large temporary costs page faults on the CPU)
        hit = torch.minimum(half_chord_sq, along)
        hit = torch.gt(hit, 0.0, out=hit)
        half_chord = half_chord_sq.clamp_min_(_TINY).sqrt_()
        return along.sub_(half_chord).sub_(max_range).mul_(hit).add_(max_range)
    hit = mask_gt(torch.minimum(half_chord_sq, along), 0.0)
    half_chord = half_chord_sq.clamp_min(_TINY).sqrt()
    max_range = _as_tensor(max_range, along)
    return torch.addcmul(max_range, along - half_chord - max_range, hit)


#: floor of a square root's argument: far below any real half chord, and its root's gradient stays finite
_TINY = 1e-30

#: added to a missed ray's distance before the minimum over targets: no hit is ever that far
_MISS = 1e30


def ray_sphere_nearest_xy(
    ox: Tensor, oy: Tensor, cos_a: Tensor, sin_a: Tensor, cx: Tensor, cy: Tensor, radius: Scalar, max_range: Scalar,
    ignore: Optional[Tensor] = None,
) -> Tensor:
    """Distance to the nearest of the spheres along dim 0, capped at ``max_range``: ``[B, R]`` from ``[E, B, 1]`` centres.

    ``ray_sphere_xy(...).amin(0)`` clamped to ``max_range``, in two fewer
    passes over ``[E, B, R]``: a missed ray's distance is pushed out of reach
    (``+ 1e30``) instead of being blended with ``max_range``, and the cap is
    applied once, after the minimum. A hit's distance is ``along - half_chord``
    rounded once (the blend rounded it twice). ``ignore`` (float 0/1,
    broadcast like the distances) drops some (sphere, ray) pairs. With a
    gradient to keep, the per-target kernel is reduced instead.
    """
    if torch.is_grad_enabled() and any(t.requires_grad for t in (ox, oy, cos_a, sin_a, cx, cy)):
        per_target = ray_sphere_xy(ox, oy, cos_a, sin_a, cx, cy, radius, max_range)
        if ignore is not None:
            per_target = torch.where(ignore > 0, float("inf"), per_target)
        return per_target.amin(dim=0).clamp_max(max_range)
    distance = ray_sphere_reach_xy(ox, oy, cos_a, sin_a, cx, cy, radius)
    if ignore is not None:
        distance = distance.add_(ignore, alpha=_MISS)
    return distance.amin(dim=0).clamp_max_(max_range)


def ray_sphere_reach_xy(ox: Tensor, oy: Tensor, cos_a: Tensor, sin_a: Tensor, cx: Tensor, cy: Tensor,
                        radius: Scalar) -> Tensor:
    """Distance along each ray to each sphere, a miss pushed out of reach (``+ 1e30``); all broadcast.

    The per-target terms of :func:`ray_sphere_nearest_xy` before its minimum
    (no gradient kept): the grid cast (:mod:`vmas_ros.simulator.lidar_grid`)
    takes its own minimum over the spheres near each lidar, and computing each
    (ray, sphere) distance with the same arithmetic keeps the two casts equal.
    """
    to_cx, to_cy = cx - ox, cy - oy
    along = torch.addcmul(to_cx * cos_a, to_cy, sin_a)
    beyond_sq = torch.addcmul(to_cx * to_cx, to_cy, to_cy) - radius * radius
    half_chord_sq = torch.addcmul(-beyond_sq, along, along)
    miss = torch.minimum(half_chord_sq, along)
    miss = torch.le(miss, 0.0, out=miss)  # 1 where the line passes wide or the sphere is behind
    return along.sub_(half_chord_sq.clamp_min_(_TINY).sqrt_()).add_(miss, alpha=_MISS)


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
    return ray_box_xy(
        origin[..., 0], origin[..., 1], torch.cos(angle), torch.sin(angle), center[..., 0], center[..., 1],
        torch.cos(rot), torch.sin(rot), _as_tensor(length, origin), _as_tensor(width, origin),
        _as_tensor(max_range, origin),
    )


def _slab(local_origin: Tensor, local_dir: Tensor, half: Tensor) -> Tuple[Tensor, Tensor]:
    """Entry and exit parameters ``(lo, hi)`` of a ray in the slab ``|x| <= half`` along one axis."""
    flat = local_dir == 0
    dir_safe = torch.where(flat, 1.0, local_dir)
    t_a = (-half - local_origin) / dir_safe
    t_b = (half - local_origin) / dir_safe
    inside = local_origin.abs() < half
    unbounded = torch.where(inside, -math.inf, math.inf)
    lo = torch.where(flat, unbounded, torch.minimum(t_a, t_b))
    hi = torch.where(flat, -unbounded, torch.maximum(t_a, t_b))
    return lo, hi


def ray_box_xy(
    ox: Tensor, oy: Tensor, cos_a: Tensor, sin_a: Tensor, cx: Tensor, cy: Tensor,
    cos_rot: Tensor, sin_rot: Tensor, length: Scalar, width: Scalar, max_range: Scalar,
) -> Tensor:
    """:func:`ray_box` on separate x/y components; the box's heading comes as its cosine and sine."""
    rel_x, rel_y = ox - cx, oy - cy
    # into the box frame: rotation by -rot
    local_ox, local_oy = rel_x * cos_rot + rel_y * sin_rot, rel_y * cos_rot - rel_x * sin_rot
    local_dx, local_dy = cos_a * cos_rot + sin_a * sin_rot, sin_a * cos_rot - cos_a * sin_rot
    lo_x, hi_x = _slab(local_ox, local_dx, length / 2)
    lo_y, hi_y = _slab(local_oy, local_dy, width / 2)
    t_near, t_far = torch.maximum(lo_x, lo_y), torch.minimum(hi_x, hi_y)
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
    return ray_segment_xy(
        origin[..., 0], origin[..., 1], torch.cos(angle), torch.sin(angle), center[..., 0], center[..., 1],
        torch.cos(rot), torch.sin(rot), _as_tensor(length, origin), _as_tensor(max_range, origin),
    )


def ray_segment_xy(
    ox: Tensor, oy: Tensor, cos_a: Tensor, sin_a: Tensor, cx: Tensor, cy: Tensor,
    cos_rot: Tensor, sin_rot: Tensor, length: Scalar, max_range: Scalar,
) -> Tensor:
    """:func:`ray_segment` on separate x/y components; the segment's heading as its cosine and sine."""
    r_x, r_y = cos_rot * length, sin_rot * length
    w_x, w_y = ox - cx, oy - cy
    rxs = r_x * sin_a - r_y * cos_a
    parallel = rxs == 0
    rxs_safe = torch.where(parallel, 1.0, rxs)
    t = (w_x * sin_a - w_y * cos_a) / rxs_safe  # position on the segment, in units of its length
    u = (w_x * r_y - w_y * r_x) / rxs_safe  # distance along the ray
    hit = ~parallel & (t >= -0.5) & (t <= 0.5) & (u >= 0)
    return torch.where(hit, u, max_range)
