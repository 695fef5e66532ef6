"""Sphere-sphere contacts: the centres are the contact points.

No broad-phase gate: for two spheres the broad phase's reach is the sum of
the radii, the contact distance itself, so every active contact passes it.
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator.geometry import norm_xy
from vmas_ros.simulator.masks import mask_ge, mask_le, zero_like
from vmas_ros.simulator.physics.collision.contact import MIN_CONTACT_DIST, PairForces, softplus_of_overlap
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import PairTable


def forces(pair: PairTable, q: Tensor, params: StepParams, exact: bool) -> PairForces:
    """Forces ``[2, P, B]`` on each pair's first sphere (the second gets the opposite), from ``q`` ``[3, N, B]``.

    With ``exact``, the contact model's arithmetic in VMAS's order and
    :func:`~vmas_ros.simulator.geometry.norm_xy`'s rounding of lengths, summed
    in VMAS's order: stiff worlds (joints) amplify a last-bit difference.
    Otherwise lengths are ``sqrt(dx * dx + dy * dy)`` and the force is one
    scalar per pair and env times the offset, about a quarter fewer passes over
    ``[P, B]``; the two agree to float rounding.
    """
    margin = params.contact_margin
    xy = q[:2]
    d = torch.index_select(xy, 1, pair.index_a) - torch.index_select(xy, 1, pair.index_b)
    dist_min = pair.contact_distance
    if exact:
        dist = norm_xy(d[0], d[1])
        penetration = torch.logaddexp(zero_like(dist), (dist_min - dist) / margin) * margin
        scale = penetration * (mask_ge(dist, MIN_CONTACT_DIST) * mask_le(dist, dist_min))
        on_a = d * params.collision_force / dist.clamp_min(1e-8) * scale
        return PairForces(on_a, -on_a)
    dist = torch.addcmul(d[0] * d[0], d[1], d[1]).sqrt_()
    active = mask_ge(dist, MIN_CONTACT_DIST).mul_(mask_le(dist, dist_min))
    scale = softplus_of_overlap((dist_min - dist) / margin).mul_(active).div_(dist.clamp_min(1e-8))
    return PairForces(d * scale.mul_(params.collision_force * margin))
