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

Integration works on ``[N, B, 2]`` vectors; the contact and joint kernels
(:mod:`vmas_ros.simulator.contacts`) work on planar ``[P, B]`` components, where
their long chains of arithmetic run on contiguous data, and hand back forces
that are stacked once per kernel for the scatter.

Nothing here loops over envs or entity pairs in Python, and nothing reads a
tensor back to the host: the number of kernels per step depends only on how
many shape-pair kinds and joints the world has. That also makes :func:`step`
a fixed-shape function that ``torch.compile`` can fuse (``World.compile_physics``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator import contacts
from vmas_ros.simulator.tables import PairTable, WorldTables
from vmas_ros.simulator.utils import TorchUtils

#: r x f with a trailing size-1 dim, the torque of force f applied at lever arm r
cross = TorchUtils.cross


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
    #: "batch": a pair near in any env interacts in every env (VMAS 1.5, bit parity);
    #: "env": each env decides for itself (envs independent of each other)
    broad_phase: str = "batch"


@dataclass
class BodyState:
    """State of all entities: pos/vel [N, B, 2], rot/ang_vel [N, B, 1]."""

    pos: Tensor
    vel: Tensor
    rot: Tensor
    ang_vel: Tensor


def pair_forces(pair: PairTable, state: BodyState, params: StepParams) -> Tuple[Tensor, Tensor, Tensor, Tensor]:
    """Contact forces [P, B, 2] and torques [P, B, 1] on both members of each pair of one kernel.

    A vector-layout view of :func:`vmas_ros.simulator.contacts.pair_contact`, for
    tests and tools. Broad phase: see :class:`StepParams` (``broad_phase``).
    """
    x, y = state.pos[..., 0].contiguous(), state.pos[..., 1].contiguous()
    fax, fay, fbx, fby, t_a, t_b = contacts.pair_contact(pair, x, y, state.rot[..., 0].contiguous(), params)
    zero = torch.zeros_like(fax)
    t_a, t_b = (zero if t is None else t for t in (t_a, t_b))
    return (torch.stack([fax, fay], dim=-1), torch.stack([fbx, fby], dim=-1), t_a.unsqueeze(-1), t_b.unsqueeze(-1))


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


def friction(vel: Tensor, coeff: Tensor, mass: Tensor, sub_dt: float) -> Tensor:
    """Coulomb-like friction opposing ``vel``, never strong enough to reverse it in one substep."""
    speed = torch.linalg.vector_norm(vel, dim=-1, keepdim=True)
    moving = speed != 0
    limit = torch.minimum(coeff * mass, vel.abs() / sub_dt * mass)
    force = -(vel / torch.where(moving, speed, 1e-8)) * limit
    return torch.where(moving, force, 0.0)


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
    fixed = None if fixed_rotation is None else fixed_rotation[..., 0]
    for substep in range(params.substeps):
        force = action_force
        torque = action_torque
        if tables.has_friction:
            force = force + friction(vel, tables.linear_friction, tables.mass, sub_dt)
            torque = torque + friction(ang_vel, tables.angular_friction, tables.inertia, sub_dt)
        if tables.has_gravity:
            force = force + tables.gravity_force
        if tables.joints is not None or tables.pairs:
            # contact and joint kernels run on planar components (see contacts.py)
            x, y, angle = pos[..., 0], pos[..., 1], rot[..., 0]
        if tables.joints is not None:
            jt = tables.joints
            fx, fy, t_a, t_b = contacts.joint_forces(jt, x, y, angle, fixed, params)
            f_a = torch.stack([fx, fy], dim=-1)
            force = scatter_pairs(force, jt.index_ab, f_a, -f_a)
            torque = scatter_pairs(torque, jt.index_ab, t_a.unsqueeze(-1), t_b.unsqueeze(-1))
        for pair in tables.pairs:
            fax, fay, fbx, fby, t_a, t_b = contacts.pair_contact(pair, x, y, angle, params)
            force = scatter_pairs(force, pair.index_ab, torch.stack([fax, fay], dim=-1), torch.stack([fbx, fby], dim=-1))
            if t_a is not None or t_b is not None:  # both None: zero by construction (two spheres)
                zero = torch.zeros_like(fax)
                torque = scatter_pairs(torque, pair.index_ab, (zero if t_a is None else t_a).unsqueeze(-1),
                                       (zero if t_b is None else t_b).unsqueeze(-1))

        if substep == 0:
            keep = _keep_fraction(tables)
            vel = vel * keep
            ang_vel = ang_vel * keep
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


def _keep_fraction(tables: WorldTables) -> Tensor:
    """``1 - drag`` per entity [N, 1, 1], computed once per tables (the same float as computing it each step)."""
    keep = getattr(tables, "_keep_cache", None)
    if keep is None:
        keep = tables._keep_cache = 1 - tables.drag
    return keep


def _clamp_to_bounds(pos: Tensor, x_semidim: Optional[float], y_semidim: Optional[float]) -> Tensor:
    x, y = pos[..., 0], pos[..., 1]
    if x_semidim is not None:
        x = x.clamp(-x_semidim, x_semidim)
    if y_semidim is not None:
        y = y.clamp(-y_semidim, y_semidim)
    return torch.stack([x, y], dim=-1)
