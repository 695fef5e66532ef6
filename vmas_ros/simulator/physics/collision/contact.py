"""The soft contact model every collision kernel shares, and the pieces of its arithmetic.

Contact forces are the soft penetration force of MPE/VMAS (paper, "The VMAS
platform"): between two shapes whose closest points are ``dist`` apart,

    f = c * n * k * log(1 + exp(-(dist - dist_min) / k))   while dist <= dist_min

along the unit vector ``n`` from one point to the other, with ``c`` the
collision force and ``k`` the contact margin. Joints use the same model as a
spring (attractive beyond their rest length).

Every quantity is a separate contiguous ``[P, B]`` tensor per component
(``x``, ``y``), not a ``[P, B, 2]`` vector: on the CPU an op whose innermost
dim has two elements cannot be vectorised. Masks are float 0/1 tensors
(:mod:`vmas_ros.simulator.masks`). The float arithmetic is ordered like VMAS
1.5's: contacts switch on discontinuously at ``dist == dist_min``, and stiff
joints amplify one-ulp differences.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.geometry import norm_xy
from vmas_ros.simulator.masks import mask_eq, mask_ge, mask_le, select, zero_like
from vmas_ros.simulator.tracing import tracing

#: below this centre distance a contact (or joint) exerts no force: its direction is undefined
MIN_CONTACT_DIST = 1e-6


@dataclass
class PairForces:
    """What one collision kernel exerts on its pairs, ``[C, P, B]`` per side.

    ``C`` is 2 (fx, fy: spheres, no torque about their centres) or 3 (fx, fy,
    torque). ``on_b`` None means exactly ``-on_a``, summed in whichever order
    is fastest; given, both sides are added in VMAS's order (pair by pair).
    """

    on_a: Tensor
    on_b: Optional[Tensor] = None


def rows(t: Tensor, index: Tensor) -> Tensor:
    """``t[index]`` for a 1-D long ``index``: ``index_select`` runs several times faster than advanced
    indexing on the CPU for [P, B] gathers, with the same values and gradients."""
    return torch.index_select(t, 0, index)


def centres(pair, q: Tensor) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """The centres ``(xa, ya, xb, yb)`` of every pair's two members, each ``[P, B]``, from ``q`` ``[3, N, B]``."""
    ia, ib = pair.index_a, pair.index_b
    return rows(q[0], ia), rows(q[1], ia), rows(q[0], ib), rows(q[1], ib)


def cross(rx: Tensor, ry: Tensor, fx: Tensor, fy: Tensor) -> Tensor:
    """Torque ``r x f`` of force ``f`` applied at lever arm ``r``."""
    return rx * fy - ry * fx


def softplus_of_overlap(overlap: Tensor) -> Tensor:
    """``log(1 + exp(overlap))`` where ``overlap >= 0``, and a finite stand-in elsewhere.

    A repulsive contact is active only where ``dist <= dist_min``, i.e. where
    its scaled overlap ``(dist_min - dist) / margin`` is non-negative; other
    entries are masked to zero afterwards, so their value only needs to be
    finite. There ``x - log(sigmoid(x))`` equals ``log(1 + exp(x))`` to float
    rounding, and this torch build vectorises ``sigmoid`` and ``log`` far
    better than ``logaddexp``. Clamping at 0 keeps ``sigmoid`` away from
    underflow (``log(0)``).
    """
    x = overlap.clamp_min(0.0)
    if x.requires_grad and torch.is_grad_enabled():
        return x - torch.sigmoid(x).log()  # autograd keeps sigmoid's output
    return x.sub_(torch.sigmoid(x).log_())


def soft_contact(
    dx: Tensor, dy: Tensor, dist: Tensor, dist_min: Tensor, strength: float, margin: float,
    attractive: bool = False, gate: Optional[Tensor] = None, exact: bool = True,
) -> Tuple[Tensor, Tensor]:
    """Force ``(fx, fy)`` on ``a`` from the soft penetration model; ``b`` gets the opposite.

    ``(dx, dy)`` is ``a - b`` and ``dist`` its length. Repulsive: pushes ``a``
    away while ``dist <= dist_min``; attractive (joints): pulls ``a`` back
    while ``dist >= dist_min``. ``gate`` (float 0/1) switches the contact off
    where it is 0 (the broad phase). ``exact``: VMAS's ``logaddexp``;
    otherwise (repulsive only) :func:`softplus_of_overlap`.
    """
    sign = -1.0 if attractive else 1.0
    if exact or attractive:
        penetration = torch.logaddexp(zero_like(dist), (dist_min - dist) * sign / margin) * margin
    else:
        penetration = softplus_of_overlap((dist_min - dist) / margin) * margin
    active = mask_ge(dist, MIN_CONTACT_DIST) * (mask_le(dist, dist_min) if not attractive else mask_ge(dist, dist_min))
    if gate is not None:
        active = active * gate
    scale = penetration * active
    # below MIN_CONTACT_DIST the contact is inactive, so clamping the divisor changes no active force
    safe = dist.clamp_min(1e-8)
    coeff = sign * strength
    return coeff * dx / safe * scale, coeff * dy / safe * scale


class Pushes:
    """The repulsive contact between point pairs of one kernel's shape pairs, behind its broad phase.

    Built from the shapes' centres ``[P, B]``: a pair whose bounding circles
    (``reach``) do not overlap exerts nothing. ``"batch"`` broad phase keeps a
    pair in every env as soon as it is near in any env (VMAS 1.5, bit parity);
    ``"env"`` decides per env.
    """

    def __init__(self, dx: Tensor, dy: Tensor, reach: Tensor, params, length: Callable = norm_xy) -> None:
        near = mask_le(length(dx, dy), reach)
        if params.broad_phase == "batch":
            near = near_in_any_env(near) if tracing() else near.amax(dim=1, keepdim=True)
        self.gate, self.length = near, length
        self.strength, self.margin = params.collision_force, params.contact_margin

    def __call__(self, ax: Tensor, ay: Tensor, bx: Tensor, by: Tensor, dist_min: Tensor) -> Tuple[Tensor, Tensor]:
        """Force on the first point from the second one (both given as points)."""
        dx, dy = ax - bx, ay - by
        return soft_contact(dx, dy, self.length(dx, dy), dist_min, self.strength, self.margin, gate=self.gate)


@torch.library.custom_op("vmas_ros::near_in_any_env", mutates_args=())
def near_in_any_env(near: Tensor) -> Tensor:
    """``near.amax(dim=1, keepdim=True)`` as an op the compiler cannot fuse.

    Fused into the contact kernel that consumes it, this one reduction across
    the batch made inductor vectorise the whole kernel along the few pairs
    instead of the many envs; kept apart, the kernel runs along the envs.
    """
    return near.amax(dim=1, keepdim=True)


@near_in_any_env.register_fake
def _(near: Tensor) -> Tensor:
    return near.new_empty(near.shape[0], 1)


def solid_inner(
    out_x: Tensor, out_y: Tensor, surf_x: Tensor, surf_y: Tensor, cen_x: Tensor, cen_y: Tensor, solid: Tensor,
) -> Tuple[Tensor, Tensor, Tensor]:
    """Contact anchor and extra distance that make a solid box push from its inside.

    For a solid box (``solid`` 1) the surface point moves further along
    ``v = surface - outside`` by the projection of ``centre - surface`` on ``v``
    (see :func:`vmas_ros.simulator.geometry.solid_box_inner_point`); a hollow box
    pushes from its surface with no extra distance.
    """
    vx, vy = surf_x - out_x, surf_y - out_y
    ux, uy = cen_x - surf_x, cen_y - surf_y
    v_norm = norm_xy(vx, vy)
    degenerate = mask_eq(v_norm, 0.0)  # the outside point lies on the surface
    v_safe = v_norm + degenerate  # exact: v_norm + 0, or 0 + 1
    depth_signed = (vx * ux + vy * uy) / v_safe * (1 - degenerate)
    inner_x = surf_x + (vx / v_safe) * depth_signed
    inner_y = surf_y + (vy / v_safe) * depth_signed
    return select(solid, inner_x, surf_x), select(solid, inner_y, surf_y), depth_signed.abs() * solid


def with_torques(fax: Tensor, fay: Tensor, t_a: Tensor, fbx: Tensor, fby: Tensor, t_b: Optional[Tensor]) -> PairForces:
    """Both sides' ``[3, P, B]`` (fx, fy, torque); a side without torque (a sphere) gets zeros."""
    if t_b is None:
        t_b = torch.zeros_like(fax)
    return PairForces(torch.stack([fax, fay, t_a]), torch.stack([fbx, fby, t_b]))
