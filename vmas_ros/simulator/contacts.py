"""Contact and joint forces of the batched step, on planar (structure-of-arrays) tensors.

Every quantity is a separate contiguous ``[rows, batch]`` tensor per component
(``x``, ``y``), not a ``[rows, batch, 2]`` vector: on the CPU an op whose
innermost dim has two elements cannot be vectorised, a ``[rows, batch, 1]``
factor broadcast against one is slower still, and a reduction over such a dim
(a dot product written ``(a * b).sum(-1)``) is a slow path of its own. Masks
are float 0/1 tensors made by comparisons with a float ``out=`` and applied by
multiplication: ``torch.where`` and bool-producing comparisons run an order of
magnitude slower than arithmetic on the CPU build we ship against, and for
finite operands ``a * 1 = a`` and ``a * 0 + b = b`` exactly, so results are
bit-identical to the masked versions.

The float arithmetic of each kernel is ordered like VMAS 1.5's (contacts switch
on discontinuously at ``dist == dist_min`` and stiff joints amplify one-ulp
differences), and distances use :func:`norm`, which rounds like
``torch.linalg.vector_norm`` over a ``[..., 2]`` vector.
"""
from __future__ import annotations

from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.tables import JointTable, PairTable
from vmas_ros.simulator.utils import LINE_MIN_DIST

#: below this centre distance a contact (or joint) exerts no force: its direction is undefined
MIN_CONTACT_DIST = 1e-6

#: per pair, the forces on a (x, y), on b (x, y) and the torques on a and b; a torque that is
#: zero by construction (about a sphere's centre) is None
PairForces = Tuple[Tensor, Tensor, Tensor, Tensor, Optional[Tensor], Optional[Tensor]]


def norm(x: Tensor, y: Tensor) -> Tensor:
    """Length of the vectors ``(x, y)``, rounded exactly as ``torch.linalg.vector_norm`` rounds it.

    ``sqrt(x * x + y * y)`` differs from it in the last bit for about a fifth
    of all inputs, and contact forces switch on at a distance threshold.
    """
    return torch.linalg.vector_norm(torch.stack([x, y], dim=-1), dim=-1)


def _hypot(x: Tensor, y: Tensor) -> Tensor:
    """``sqrt(x * x + y * y)``: the fast length (see :func:`norm` for the VMAS-rounded one)."""
    return torch.addcmul(x * x, y, y).sqrt_()


def mask_ge(a: Tensor, b) -> Tensor:
    """``a >= b`` as float 0/1 (broadcast), without a bool intermediate."""
    return torch.ge(a, b, out=a.new_empty(_broadcast_shape(a, b)))


def mask_le(a: Tensor, b) -> Tensor:
    """``a <= b`` as float 0/1 (broadcast), without a bool intermediate."""
    return torch.le(a, b, out=a.new_empty(_broadcast_shape(a, b)))


def mask_lt(a: Tensor, b) -> Tensor:
    """``a < b`` as float 0/1 (broadcast), without a bool intermediate."""
    return torch.lt(a, b, out=a.new_empty(_broadcast_shape(a, b)))


def mask_gt(a: Tensor, b) -> Tensor:
    """``a > b`` as float 0/1 (broadcast), without a bool intermediate."""
    return torch.gt(a, b, out=a.new_empty(_broadcast_shape(a, b)))


def mask_ne(a: Tensor, b) -> Tensor:
    """``a != b`` as float 0/1 (broadcast), without a bool intermediate."""
    return torch.ne(a, b, out=a.new_empty(_broadcast_shape(a, b)))


def mask_eq(a: Tensor, b) -> Tensor:
    """``a == b`` as float 0/1 (broadcast), without a bool intermediate."""
    return torch.eq(a, b, out=a.new_empty(_broadcast_shape(a, b)))


def _broadcast_shape(a: Tensor, b) -> Tuple[int, ...]:
    if not isinstance(b, Tensor) or b.shape == a.shape:
        return tuple(a.shape)
    if torch.compiler.is_compiling():  # the plain-Python loop breaks the compiled graph
        return tuple(torch.broadcast_shapes(a.shape, b.shape))
    return geo.broadcast_shape(a.shape, b.shape)


def rows(t: Tensor, index: Tensor) -> Tensor:
    """``t[index]`` for a 1-D long ``index``: ``index_select`` runs about 5x faster than advanced
    indexing on the CPU for [P, B] gathers, with the same values and gradients."""
    return torch.index_select(t, 0, index)


def select(mask: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """``where(mask, a, b)`` for a float 0/1 ``mask`` and finite ``a``, ``b`` (exact)."""
    return a * mask + b * (1 - mask)


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
    better than ``logaddexp`` (about 2.3x faster over ``[pairs, envs]``).
    Clamping at 0 keeps ``sigmoid`` away from underflow (``log(0)``).
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

    ``(dx, dy)`` is ``a - b`` and ``dist`` its :func:`norm`. Repulsive: pushes
    ``a`` away while ``dist <= dist_min``; attractive (joints): pulls ``a`` back
    while ``dist >= dist_min``. Magnitude ``strength * margin * log(1 + exp(+-(dist_min - dist) / margin))``.
    ``gate`` (float 0/1) switches the contact off where it is 0 (the broad phase).
    ``exact``: VMAS's ``logaddexp``; otherwise (repulsive only) :func:`softplus_of_overlap`.
    """
    sign = -1.0 if attractive else 1.0
    if exact or attractive:
        penetration = torch.logaddexp(_zero(dist), (dist_min - dist) * sign / margin) * margin
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


def _gate(gap: Tensor, reach: Tensor, broad_phase: str) -> Tensor:
    """Broad phase as a float mask: 1 where the pair's bounding circles overlap.

    ``"batch"`` keeps a pair in every env as soon as it is near in any env (VMAS
    1.5's behaviour, for bit parity); ``"env"`` decides per env.
    """
    near = mask_le(gap, reach)
    if broad_phase == "batch":
        near = near_in_any_env(near) if torch.compiler.is_compiling() else near.amax(dim=1, keepdim=True)
    return near


@torch.library.custom_op("vmas_ros::near_in_any_env", mutates_args=())
def near_in_any_env(near: Tensor) -> Tensor:
    """``near.amax(dim=1, keepdim=True)`` as an op the compiler cannot fuse.

    Fused into the contact kernel that consumes it, this one reduction across
    the batch made inductor vectorise the whole kernel along the few pairs
    instead of the many envs (box-sphere contacts at 10,000 envs: 790 us
    compiled against 210 us eager); kept apart, the kernel runs along the envs.
    """
    return near.amax(dim=1, keepdim=True)


@near_in_any_env.register_fake
def _(near: Tensor) -> Tensor:
    return near.new_empty(near.shape[0], 1)


def _vectors(x: Tensor, y: Tensor) -> Tensor:
    return torch.stack([x, y], dim=-1)


def sphere_pair_forces(pair: PairTable, xy: Tensor, params, exact: bool = False) -> Tensor:
    """Force ``[2, P, B]`` on the first sphere of each pair (the second gets the opposite), from positions ``[2, N, B]``.

    The common kernel in few calls. With ``exact``, :func:`soft_contact`'s
    float arithmetic in VMAS's order and :func:`norm`'s rounding of lengths:
    stiff worlds (joints) amplify a last-bit difference, but the norm needs an
    interleaving copy that costs more than the rest of the kernel. Otherwise
    lengths are ``sqrt(dx * dx + dy * dy)`` and the force is one scalar per
    pair and env times the offset, about a quarter fewer passes over
    ``[P, B]``; the two agree to float rounding.
    No broad-phase gate: for two spheres the broad phase's reach is the sum of
    the radii, the contact distance itself, so every active contact passes it.
    """
    margin = params.contact_margin
    d = torch.index_select(xy, 1, pair.index_a) - torch.index_select(xy, 1, pair.index_b)
    dist_min = pair.contact_distance
    if exact:
        dist = norm(d[0], d[1])
        penetration = torch.logaddexp(_zero(dist), (dist_min - dist) / margin) * margin
        scale = penetration * (mask_ge(dist, MIN_CONTACT_DIST) * mask_le(dist, dist_min))
        return d * params.collision_force / dist.clamp_min(1e-8) * scale
    dist = torch.addcmul(d[0] * d[0], d[1], d[1]).sqrt_()
    active = mask_ge(dist, MIN_CONTACT_DIST).mul_(mask_le(dist, dist_min))
    scale = softplus_of_overlap((dist_min - dist) / margin).mul_(active).div_(dist.clamp_min(1e-8))
    return d * scale.mul_(params.collision_force * margin)


def _zero(like: Tensor) -> Tensor:
    """A cached 0-dim zero on ``like``'s device and dtype (saves a call per contact kernel)."""
    key = (like.device, like.dtype)
    zero = _ZEROS.get(key)
    if zero is None:
        zero = _ZEROS[key] = torch.zeros((), device=like.device, dtype=like.dtype)
    return zero


_ZEROS: dict = {}


def pair_contact(pair: PairTable, x: Tensor, y: Tensor, rot: Tensor, params, exact: bool = True) -> PairForces:
    """Contact forces and torques ``[P, B]`` of one kernel's pairs, from planar state ``[N, B]``.

    ``exact``: VMAS's float arithmetic and rounding throughout (worlds with
    joints, where a last-bit difference grows). Otherwise box-sphere contacts
    are found in the box frame
    (:func:`~vmas_ros.simulator.geometry.closest_point_on_box_boundary_in_frame`)
    with lengths ``sqrt(x * x + y * y)``: the same forces to float rounding, in
    far fewer passes.
    """
    p = pair.params
    ia, ib = pair.index_a, pair.index_b
    xa, ya, xb, yb = rows(x, ia), rows(y, ia), rows(x, ib), rows(y, ib)
    dx, dy = xa - xb, ya - yb
    # the fast length only where the kernel is rewritten anyway: the candidate searches of lines and
    # box-box pick among near-equal distances, so their rounding stays VMAS's
    length = _hypot if not exact and pair.kind == ("box", "sphere") else norm
    gap = length(dx, dy)
    gate = _gate(gap, p["reach"], params.broad_phase)
    strength, margin = params.collision_force, params.contact_margin
    kind = pair.kind

    def push(ax, ay, bx, by, dist_min):
        """Force on the first point from the second one (both given as points)."""
        ddx, ddy = ax - bx, ay - by
        return soft_contact(ddx, ddy, length(ddx, ddy), dist_min, strength, margin, gate=gate)

    if kind == ("sphere", "sphere"):
        # the contact points are the centres: reuse the broad phase's offset and distance
        fx, fy = soft_contact(dx, dy, gap, p["a_radius"] + p["b_radius"], strength, margin, gate=gate, exact=exact)
        return fx, fy, -fx, -fy, None, None
    ra, rb = rows(rot, ia), rows(rot, ib)
    if kind == ("line", "sphere"):
        qx, qy = geo.closest_point_on_segment_xy(xa, ya, ra, p["a_length"], xb, yb)
        fbx, fby = push(xb, yb, qx, qy, p["b_radius"] + LINE_MIN_DIST)
        return -fbx, -fby, fbx, fby, cross(qx - xa, qy - ya, -fbx, -fby), None
    if kind == ("box", "sphere"):
        closest = geo.closest_point_on_box_boundary_xy if exact else geo.closest_point_on_box_boundary_in_frame
        sx, sy = closest(xa, ya, ra, p["a_length"], p["a_width"], xb, yb)
        ax, ay, depth = _solid_inner(xb, yb, sx, sy, xa, ya, p["a_solid"])
        fbx, fby = push(xb, yb, ax, ay, p["b_radius"] + LINE_MIN_DIST + depth)
        return -fbx, -fby, fbx, fby, cross(sx - xa, sy - ya, -fbx, -fby), None
    # the remaining kernels search many candidate point pairs; they run on [P, B, 2] vectors
    pa, pb = _vectors(xa, ya), _vectors(xb, yb)
    if kind == ("line", "line"):
        ca, cb = geo.closest_points_segment_segment(pa, ra, p["a_length"], pb, rb, p["b_length"])
        (cax, cay), (cbx, cby) = ca.unbind(-1), cb.unbind(-1)
        fx, fy = push(cax, cay, cbx, cby, torch.full_like(p["a_length"], LINE_MIN_DIST))
        return fx, fy, -fx, -fy, cross(cax - xa, cay - ya, fx, fy), cross(cbx - xb, cby - yb, -fx, -fy)
    if kind == ("box", "line"):
        on_box, on_line = geo.closest_points_box_segment(pa, ra, p["a_length"], p["a_width"], pb, rb, p["b_length"])
        (bx_, by_), (lx, ly) = on_box.unbind(-1), on_line.unbind(-1)
        ax, ay, depth = _solid_inner(lx, ly, bx_, by_, xa, ya, p["a_solid"])
        fx, fy = push(ax, ay, lx, ly, LINE_MIN_DIST + depth)
        return fx, fy, -fx, -fy, cross(bx_ - xa, by_ - ya, fx, fy), cross(lx - xb, ly - yb, -fx, -fy)
    if kind == ("box", "box"):
        on_a, on_b = geo.closest_points_box_box(
            pa, ra, p["a_length"], p["a_width"], pb, rb, p["b_length"], p["b_width"]
        )
        (oax, oay), (obx, oby) = on_a.unbind(-1), on_b.unbind(-1)
        aax, aay, depth_a = _solid_inner(obx, oby, oax, oay, xa, ya, p["a_solid"])
        abx, aby, depth_b = _solid_inner(oax, oay, obx, oby, xb, yb, p["b_solid"])
        fx, fy = push(aax, aay, abx, aby, depth_a + depth_b + LINE_MIN_DIST)
        return fx, fy, -fx, -fy, cross(oax - xa, oay - ya, fx, fy), cross(obx - xb, oby - yb, -fx, -fy)
    raise KeyError(f"no collision kernel for {kind}")


def _solid_inner(
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
    v_norm = norm(vx, vy)
    degenerate = mask_eq(v_norm, 0.0)  # the outside point lies on the surface
    v_safe = v_norm + degenerate  # exact: v_norm + 0, or 0 + 1
    depth_signed = (vx * ux + vy * uy) / v_safe * (1 - degenerate)
    inner_x = surf_x + (vx / v_safe) * depth_signed
    inner_y = surf_y + (vy / v_safe) * depth_signed
    return select(solid, inner_x, surf_x), select(solid, inner_y, surf_y), depth_signed.abs() * solid


def joint_forces(
    joints: JointTable, x: Tensor, y: Tensor, rot: Tensor, fixed_rotation: Tensor, params,
) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Forces ``(fx, fy)`` on the a side (b gets the opposite) and torques on a and b, each ``[J, B]``."""
    ia, ib = joints.index_a, joints.index_b
    xa, ya, xb, yb, ra, rb = rows(x, ia), rows(y, ia), rows(x, ib), rows(y, ib), rows(rot, ia), rows(rot, ib)
    # anchors: body-frame offsets rotated into the world frame
    cos_a, sin_a, cos_b, sin_b = torch.cos(ra), torch.sin(ra), torch.cos(rb), torch.sin(rb)
    ax0, ay0, bx0, by0 = joints.anchor_ax, joints.anchor_ay, joints.anchor_bx, joints.anchor_by
    pax, pay = xa + (ax0 * cos_a - ay0 * sin_a), ya + (ax0 * sin_a + ay0 * cos_a)
    pbx, pby = xb + (bx0 * cos_b - by0 * sin_b), yb + (bx0 * sin_b + by0 * cos_b)
    dx, dy = pax - pbx, pay - pby
    dist = norm(dx, dy)
    rest = joints.dist.expand_as(dist)
    strength, margin = params.joint_force, params.contact_margin
    fx, fy = soft_contact(dx, dy, dist, rest, strength, margin, attractive=True)
    rx, ry = soft_contact(dx, dy, dist, rest, strength, margin)
    fx, fy = fx + rx, fy + ry
    # lever arms as (anchor point - centre), not the rotated offset itself: same rounding as VMAS
    t_a = cross(pax - xa, pay - ya, fx, fy)
    t_b = cross(pbx - xb, pby - yb, -fx, -fy)
    # rotation lock: a stiff exponential spring on the relative angle where rotation is not free
    # unlocked joints get delta 0 before the exponential: exp of a free joint's accumulated angle
    # overflows (past ~88.7 rad in float32), and inf * 0 would be NaN (exact for locked ones: delta * 1)
    delta = (ra - (rb + fixed_rotation)) * joints.locked
    magnitude = delta.abs()
    lock = params.torque_constraint_force * delta.sign() * (torch.exp(magnitude) - 1)
    lock = lock * mask_ge(magnitude, 1e-9)
    return fx, fy, t_a - lock, t_b + lock
