"""Joint forces: each joint is a stiff two-sided spring between anchor points, plus a rotation lock.

The spring is the contact model (``collision.contact.soft_contact``) twice:
attractive beyond the joint's rest distance, repulsive within it, with the
joint force as strength. Where the joint fixes the relative angle, a stiff
exponential torque drives it to its target.
"""
from __future__ import annotations

from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.geometry import norm_xy
from vmas_ros.simulator.masks import mask_ge
from vmas_ros.simulator.physics.collision.contact import cross, rows, soft_contact
from vmas_ros.simulator.physics.scatter import add_pairs
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import JointTable

__all__ = ["add_joint_forces", "fixed_rotations", "joint_forces"]


def add_joint_forces(force: Tensor, joints: Optional[JointTable], q: Tensor, fixed_rotation: Optional[Tensor],
                     params: StepParams) -> None:
    """Add every joint's forces and torques onto ``force`` ``[3, N, B]`` in place, in VMAS's order.

    ``fixed_rotation``: the joints' target relative angles ``[J, B]``.
    """
    if joints is None:
        return
    fx, fy, t_a, t_b = joint_forces(joints, q[0], q[1], q[2], fixed_rotation, params)
    add_pairs(force, joints, torch.stack([fx, fy, t_a]), torch.stack([-fx, -fy, t_b]))


def joint_forces(
    joints: JointTable, x: Tensor, y: Tensor, rot: Tensor, fixed_rotation: Tensor, params: StepParams,
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
    dist = norm_xy(dx, dy)
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


def fixed_rotations(constraints, batch_dim: int, device) -> Tensor:
    """``[J, B, 1]``: each joint's target relative angle (a number, or a tensor when the joint follows
    its line), the step's ``fixed_rotation`` input."""
    values = []
    for c in constraints:
        value = c.fixed_rotation
        if isinstance(value, Tensor):
            values.append(value.reshape(-1, 1).to(device).expand(batch_dim, 1))
        else:
            values.append(torch.full((batch_dim, 1), float(value), device=device))
    return torch.stack(values)
