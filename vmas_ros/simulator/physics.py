"""The batched physics step: pure functions over ``[n_entities, batch, ...]`` tensors.

Entity-major on purpose: per-entity constants (mass, limits, masks) then
broadcast over each entity's contiguous ``[batch, 2]`` block, and gathering a
pair's members is a copy of whole blocks; batch-major ``[batch, n, 2]`` made
every broadcast op run two floats at a time, 3x slower than VMAS at 30,000 envs.

One call of :func:`step` advances every env by ``dt`` with ``substeps``
semi-implicit Euler substeps (paper, "The VMAS platform"):

    f_i   = f_action + f_gravity + f_friction + sum_j f_contact(i, j) + f_joint
    v_i' = (1 - drag) v_i + f_i / m_i * dt          (drag on the first substep)
    x_i' = x_i + v_i' * dt

with the same update for the angle using torques and the moment of inertia.
Contact forces are the soft penetration force of MPE/VMAS:
``c * n * k * log(1 + exp(-(d - d_min) / k))`` while ``d <= d_min``.

Nothing here loops over envs or entity pairs in Python, and nothing reads a
tensor back to the host: the number of kernels per step depends only on how
many shape-pair kinds and joints the world has.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.tables import PairTable, WorldTables
from vmas_ros.simulator.utils import LINE_MIN_DIST, TorchUtils

#: r x f with a trailing size-1 dim, the torque of force f applied at lever arm r
cross = TorchUtils.cross

_MIN_CONTACT_DIST = 1e-6


@dataclass
class StepParams:
    """World-level constants of the step."""

    dt: float
    substeps: int
    collision_force: float
    joint_force: float
    torque_constraint_force: float
    contact_margin: float
    x_semidim: Optional[float]
    y_semidim: Optional[float]
    broad_phase: str = "batch"


@dataclass
class BodyState:
    """State of all entities: pos/vel [N, B, 2], rot/ang_vel [N, B, 1]."""

    pos: Tensor
    vel: Tensor
    rot: Tensor
    ang_vel: Tensor


def soft_contact_force(
    pos_a: Tensor, pos_b: Tensor, dist_min: Tensor, strength: float, margin: float, attractive: bool = False,
    delta: Optional[Tensor] = None, dist: Optional[Tensor] = None,
) -> Tensor:
    """Force on ``a`` (``b`` gets the opposite) from the soft penetration model.

    Repulsive: pushes ``a`` away from ``b`` while closer than ``dist_min``.
    Attractive (joints): pulls ``a`` towards ``b`` while farther than ``dist_min``.
    ``delta`` (``pos_a - pos_b``) and ``dist`` (its norm) may be passed when the caller has them.
    """
    # The operation order below is deliberate: contacts switch on at dist == dist_min,
    # so a 1-ulp difference from upstream can flip a contact. We keep VMAS's rounding.
    if delta is None:
        delta = pos_a - pos_b
    if dist is None:
        dist = torch.linalg.vector_norm(delta, dim=-1)
    sign = -1.0 if attractive else 1.0
    penetration = torch.logaddexp(dist.new_zeros(()), (dist_min - dist) * sign / margin) * margin
    force = (sign * strength) * delta / torch.where(dist > 0, dist, 1e-8).unsqueeze(-1) * penetration.unsqueeze(-1)
    inactive = dist < _MIN_CONTACT_DIST
    inactive = inactive | ((dist < dist_min) if attractive else (dist > dist_min))
    return torch.where(inactive.unsqueeze(-1), 0.0, force)


def friction(vel: Tensor, coeff: Tensor, mass: Tensor, sub_dt: float) -> Tensor:
    """Coulomb-like friction opposing ``vel``, never strong enough to reverse it in one substep."""
    speed = torch.linalg.vector_norm(vel, dim=-1, keepdim=True)
    moving = speed != 0
    limit = torch.minimum(coeff * mass, vel.abs() / sub_dt * mass)
    force = -(vel / torch.where(moving, speed, 1e-8)) * limit
    return torch.where(moving, force, 0.0)


def _solid_inner(outside: Tensor, surface: Tensor, centre: Tensor, solid: Tensor) -> Tuple[Tensor, Tensor]:
    """Contact anchor and extra distance that make a solid box push from its inside."""
    inner, depth = geo.solid_box_inner_point(outside, surface, centre)
    solid = solid.bool()
    return torch.where(solid.unsqueeze(-1), inner, surface), torch.where(solid, depth, 0.0)


def pair_forces(pair: PairTable, state: BodyState, params: StepParams) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Contact forces and torques [P, B, 2] / [P, B, 1] on both members of each pair.

    The members' positions, their offset and distance are computed once here and
    shared with the kernel (for two spheres they are the contact geometry).

    Broad phase: a pair interacts only while its centres are within the sum of
    the shapes' circumscribed radii. That cut matters in a thin band where a
    line's end or a box's corner is within ``LINE_MIN_DIST`` of another shape.
    ``params.broad_phase == "batch"`` keeps a pair in *every* env as soon as it is
    near in *any* env, which is what VMAS 1.5 does (bit-for-bit parity, but an
    env can then feel its neighbours in the batch); ``"env"`` decides per env,
    so no env depends on the others (bit-identical at equal batch size; across
    batch sizes torch's float32 kernels may round one ulp differently). Neither
    mode reads back to the host.
    """
    pa, pb = state.pos[pair.index_a], state.pos[pair.index_b]
    delta = pa - pb
    gap = torch.linalg.vector_norm(delta, dim=-1)
    f_a, f_b, t_a, t_b = _pair_contact(pair, state, params, pa, pb, delta, gap)
    near = gap <= pair.params["reach"]
    if params.broad_phase == "batch":
        near = near.any(dim=1, keepdim=True)
    near = near.unsqueeze(-1)
    # a sphere's torque (None) is zero by construction and needs no mask
    zero = None if t_a is not None and t_b is not None else pa.new_zeros(pa.shape[:-1] + (1,))
    return tuple(zero if value is None else torch.where(near, value, 0.0) for value in (f_a, f_b, t_a, t_b))


def _pair_contact(
    pair: PairTable, state: BodyState, params: StepParams, pa: Tensor, pb: Tensor, delta: Tensor, gap: Tensor,
) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Forces on a and b and torques on a and b of one kernel; a torque that is zero by
    construction (about a sphere's centre) is None."""
    p = pair.params
    force = lambda a, b, d: soft_contact_force(a, b, d, params.collision_force, params.contact_margin)  # noqa: E731
    kind = pair.kind
    if kind == ("sphere", "sphere"):
        # the contact points are the centres: reuse the broad phase's offset and distance
        f_a = soft_contact_force(pa, pb, p["a_radius"] + p["b_radius"], params.collision_force,
                                 params.contact_margin, delta=delta, dist=gap)
        return f_a, -f_a, None, None
    ra, rb = state.rot[pair.index_a, :, 0], state.rot[pair.index_b, :, 0]
    if kind == ("line", "sphere"):
        contact = geo.closest_point_on_segment(pa, ra, p["a_length"], pb)
        f_b = force(pb, contact, p["b_radius"] + LINE_MIN_DIST)
        return -f_b, f_b, cross(contact - pa, -f_b), None
    if kind == ("line", "line"):
        ca, cb = geo.closest_points_segment_segment(pa, ra, p["a_length"], pb, rb, p["b_length"])
        f_a = force(ca, cb, torch.full_like(p["a_length"], LINE_MIN_DIST))
        return f_a, -f_a, cross(ca - pa, f_a), cross(cb - pb, -f_a)
    if kind == ("box", "sphere"):
        surface = geo.closest_point_on_box_boundary(pa, ra, p["a_length"], p["a_width"], pb)
        anchor, depth = _solid_inner(pb, surface, pa, p["a_solid"])
        f_b = force(pb, anchor, p["b_radius"] + LINE_MIN_DIST + depth)
        return -f_b, f_b, cross(surface - pa, -f_b), None
    if kind == ("box", "line"):
        on_box, on_line = geo.closest_points_box_segment(pa, ra, p["a_length"], p["a_width"], pb, rb, p["b_length"])
        anchor, depth = _solid_inner(on_line, on_box, pa, p["a_solid"])
        f_a = force(anchor, on_line, LINE_MIN_DIST + depth)
        return f_a, -f_a, cross(on_box - pa, f_a), cross(on_line - pb, -f_a)
    if kind == ("box", "box"):
        on_a, on_b = geo.closest_points_box_box(
            pa, ra, p["a_length"], p["a_width"], pb, rb, p["b_length"], p["b_width"]
        )
        anchor_a, depth_a = _solid_inner(on_b, on_a, pa, p["a_solid"])
        anchor_b, depth_b = _solid_inner(on_a, on_b, pb, p["b_solid"])
        f_a = force(anchor_a, anchor_b, depth_a + depth_b + LINE_MIN_DIST)
        return f_a, -f_a, cross(on_a - pa, f_a), cross(on_b - pb, -f_a)
    raise KeyError(f"no collision kernel for {kind}")


def joint_forces(tables: WorldTables, state: BodyState, fixed_rotation: Tensor, params: StepParams):
    """Forces [J, B, 2] and torques [J, B, 1] holding joint anchors together."""
    jt = tables.joints
    pos_a, pos_b = state.pos[jt.index_a], state.pos[jt.index_b]
    rot_a, rot_b = state.rot[jt.index_a], state.rot[jt.index_b]
    anchor_a = geo.rotate(jt.anchor_a.expand_as(pos_a), rot_a[..., 0])
    anchor_b = geo.rotate(jt.anchor_b.expand_as(pos_b), rot_b[..., 0])
    point_a = pos_a + anchor_a
    point_b = pos_b + anchor_b
    dist = jt.dist.expand(point_a.shape[:-1])
    f_a = soft_contact_force(point_a, point_b, dist, params.joint_force, params.contact_margin, attractive=True)
    f_a = f_a + soft_contact_force(point_a, point_b, dist, params.joint_force, params.contact_margin)
    # lever arms as (anchor point - centre), not the rotated offset itself: same rounding as VMAS
    t_a = cross(point_a - pos_a, f_a)
    t_b = cross(point_b - pos_b, -f_a)
    # rotation lock: a stiff exponential spring on the relative angle where rotation is not free
    delta = rot_a - (rot_b + fixed_rotation)
    magnitude = delta.abs()
    lock = params.torque_constraint_force * delta.sign() * (torch.exp(magnitude) - 1)
    lock = torch.where(magnitude < 1e-9, 0.0, lock)
    locked = (~jt.rotate).view(-1, 1, 1)
    t_a = torch.where(locked, t_a - lock, t_a)
    t_b = torch.where(locked, t_b + lock, t_b)
    return f_a, -f_a, t_a, t_b


def scatter_pairs(total: Tensor, index_ab: Tensor, on_a: Tensor, on_b: Tensor) -> Tensor:
    """Add per-pair values [P, B, D] onto per-entity totals [N, B, D] in pair order (a0, b0, a1, b1, ...).

    Summing in the same order as VMAS keeps results bit-identical, which matters
    because stiff joints amplify a one-ulp difference within a few steps.
    """
    values = torch.stack([on_a, on_b], dim=1).flatten(0, 1)
    return total.index_add(0, index_ab, values)


def clamp_norm(vec: Tensor, max_norm) -> Tensor:
    """Scale vectors longer than ``max_norm`` back onto it (``inf`` means no limit).

    Rounds like VMAS (``vec / norm * max``) so speed-limited agents stay in
    bit parity, and keeps gradients finite: the unused branch never divides by
    zero or multiplies by ``inf``.
    """
    norm = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
    over = norm > max_norm
    finite_max = torch.where(torch.isfinite(torch.as_tensor(max_norm, device=vec.device)), max_norm, 0.0)
    return torch.where(over, vec / torch.where(over, norm, 1.0) * finite_max, vec)


def step(
    state: BodyState,
    tables: WorldTables,
    params: StepParams,
    action_force: Tensor,
    action_torque: Tensor,
    fixed_rotation: Optional[Tensor],
) -> BodyState:
    """Advance all envs by one ``dt``. ``action_*`` are per entity ([N, B, 2] / [N, B, 1])."""
    sub_dt = params.dt / params.substeps
    pos, vel, rot, ang_vel = state.pos, state.vel, state.rot, state.ang_vel
    for substep in range(params.substeps):
        force = action_force
        torque = action_torque
        if tables.has_friction:
            force = force + friction(vel, tables.linear_friction, tables.mass, sub_dt)
            torque = torque + friction(ang_vel, tables.angular_friction, tables.inertia, sub_dt)
        if tables.has_gravity:
            force = force + tables.gravity_force
        current = BodyState(pos, vel, rot, ang_vel)
        if tables.joints is not None:
            jt = tables.joints
            f_a, f_b, t_a, t_b = joint_forces(tables, current, fixed_rotation, params)
            force = scatter_pairs(force, jt.index_ab, f_a, f_b)
            torque = scatter_pairs(torque, jt.index_ab, t_a, t_b)
        for pair in tables.pairs:
            f_a, f_b, t_a, t_b = pair_forces(pair, current, params)
            force = scatter_pairs(force, pair.index_ab, f_a, f_b)
            if t_a is not t_b:  # the same tensor: both zero by construction (two spheres)
                torque = scatter_pairs(torque, pair.index_ab, t_a, t_b)

        if substep == 0:
            vel = vel * (1 - tables.drag)
            ang_vel = ang_vel * (1 - tables.drag)
        new_vel = vel + force / tables.mass * sub_dt
        if tables.limits_speed:
            new_vel = clamp_norm(new_vel, tables.max_speed)
        if tables.limits_velocity:
            new_vel = torch.maximum(torch.minimum(new_vel, tables.v_range), -tables.v_range)
        new_pos = pos + new_vel * sub_dt
        if params.x_semidim is not None or params.y_semidim is not None:
            new_pos = _clamp_to_bounds(new_pos, params.x_semidim, params.y_semidim)
        pos = torch.where(tables.movable, new_pos, pos)
        vel = torch.where(tables.movable, new_vel, state.vel if substep == 0 else vel)
        new_ang_vel = ang_vel + torque / tables.inertia * sub_dt
        rot = torch.where(tables.rotatable, rot + new_ang_vel * sub_dt, rot)
        ang_vel = torch.where(tables.rotatable, new_ang_vel, state.ang_vel if substep == 0 else ang_vel)
    return BodyState(pos, vel, rot, ang_vel)


def _clamp_to_bounds(pos: Tensor, x_semidim: Optional[float], y_semidim: Optional[float]) -> Tensor:
    x, y = pos[..., 0], pos[..., 1]
    if x_semidim is not None:
        x = x.clamp(-x_semidim, x_semidim)
    if y_semidim is not None:
        y = y.clamp(-y_semidim, y_semidim)
    return torch.stack([x, y], dim=-1)
