"""Semi-implicit Euler: the velocity from the force, then the position from the new velocity.

Per substep of ``sub_dt`` (paper, "The VMAS platform"), for every coordinate
of every free entity (mass ``m``, or the moment of inertia for the angle)::

    v' = keep * v + f / m * sub_dt        (keep = 1 - drag, first substep only)
    v' = limited to max_speed and v_range
    x' = x + v' * sub_dt,  clamped to the world's semidims

Held entities (landmarks, agents that cannot move or turn) keep their state.
How they are kept still is chosen once per step by :func:`hold_method`; all
methods give the same result.
"""
from __future__ import annotations

import enum
from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.geometry import norm_xy
from vmas_ros.simulator.masks import mask_gt, select
from vmas_ros.simulator.physics.constants import StepConstants
from vmas_ros.simulator.thresholds import SMALL_BATCH_ELEMENTS
from vmas_ros.simulator.tracing import tracing

__all__ = ["Hold", "differentiable", "hold_method", "integrate", "substep"]


class Hold(enum.Enum):
    """How held entities keep their state through a substep."""

    NOTHING = "every entity is free"
    WHERE = "one torch.where over the whole state (few elements: the call cost dominates)"
    ROWS = "integrate everything, then copy the held rows back"
    BLOCK = "integrate only the free entities, one block, into the new state"


def hold_method(c: StepConstants, state_elements: int) -> Hold:
    """The :class:`Hold` for a state of ``state_elements`` elements (``torch.where`` is slow per
    element on the CPU, a row copy is not, and a free block needs no copy at all)."""
    if c.free_span is not None and state_elements > SMALL_BATCH_ELEMENTS:
        return Hold.BLOCK
    if c.all_free:
        return Hold.NOTHING
    return Hold.WHERE if state_elements <= SMALL_BATCH_ELEMENTS else Hold.ROWS


def differentiable(*tensors: Tensor) -> bool:
    """Whether autograd must see these (then no ``out=`` writes: they refuse tensors that need a gradient)."""
    return torch.is_grad_enabled() and any(t.requires_grad for t in tensors)


def substep(q: Tensor, v: Tensor, v0: Tensor, force: Tensor, c: StepConstants, hold: Hold,
            first: bool) -> Tuple[Tensor, Tensor]:
    """One substep of every entity: the new ``(q, v)``, each ``[3, N, B]``.

    ``v0`` is the velocity the step started from (what held entities keep);
    ``first``: the first substep, where drag applies.
    """
    if hold is Hold.BLOCK:
        lo, hi = c.free_span
        if differentiable(q, v, force) or tracing():
            # (compiled: the cat, which the compiler fuses; out= into row slices would break its graph)
            free_q, free_v = integrate(q[:, lo:hi], v[:, lo:hi], force[:, lo:hi], c.free_block, first)
            q = torch.cat([q[:, :lo], free_q] if lo else [free_q, q[:, hi:]], dim=1)
            v = torch.cat([v[:, :lo], free_v] if lo else [free_v, v[:, hi:]], dim=1)
            return q, v
        # the free block integrates straight into its rows of the new state (no block-sized temporaries)
        new_q, new_v = torch.empty_like(q), torch.empty_like(v)
        held = slice(0, lo) if lo else slice(hi, None)
        new_q[:, held], new_v[:, held] = q[:, held], v[:, held]
        integrate(q[:, lo:hi], v[:, lo:hi], force[:, lo:hi], c.free_block, first, out=(new_q[:, lo:hi], new_v[:, lo:hi]))
        return new_q, new_v
    new_q, new_v = integrate(q, v, force, c, first)
    if hold is Hold.NOTHING:
        return new_q, new_v
    if hold is Hold.WHERE:
        return torch.where(c.free, new_q, q), torch.where(c.free, new_v, v0)
    # Hold.ROWS: copy the held (coordinate, entity) rows back, one pass
    held, shape = c.held_rows, new_q.shape
    q = new_q.flatten(0, 1).index_copy(0, held, q.flatten(0, 1).index_select(0, held)).view(shape)
    v = new_v.flatten(0, 1).index_copy(0, held, v0.flatten(0, 1).index_select(0, held)).view(shape)
    return q, v


def integrate(q: Tensor, v: Tensor, force: Tensor, c: StepConstants, first: bool,
              out: Optional[Tuple[Tensor, Tensor]] = None) -> Tuple[Tensor, Tensor]:
    """One semi-implicit Euler substep of the rows in ``q``/``v`` (``c``: their constants), limits applied.

    ``out``: ``(q, v)`` slots to write the result into (the caller checked that no gradient is kept).
    """
    # (v * keep) + force / mass * dt in VMAS's rounding (addition commutes exactly)
    if out is None:
        # in one fresh tensor: the in-place steps only touch the quotient, whose gradient needs
        # neither it nor its inputs
        new_v = (force / c.mass).mul_(c.sub_dt).add_(v * c.keep if first else v)
    else:
        # no temporaries: the quotient goes where the positions will, the damped velocity where the
        # velocities will
        quotient = torch.div(force, c.mass, out=out[0]).mul_(c.sub_dt)
        new_v = (torch.mul(v, c.keep, out=out[1]) if first else out[1].copy_(v)).add_(quotient)
    if c.limits_speed:
        speed = norm_xy(new_v[0], new_v[1])
        over = mask_gt(speed, c.max_speed)
        # VMAS's rounding: v / |v| * max where over the limit
        limited = new_v[:2] / (speed + (1 - over)) * c.finite_max_speed
        new_v = torch.cat([select(over, limited, new_v[:2]), new_v[2:]])
    if c.limits_velocity:
        new_v = torch.clamp(new_v, -c.v_range, c.v_range)
    if out is None:
        new_q = (new_v * c.sub_dt).add_(q)
        if c.semidims is not None:
            new_q = torch.clamp(new_q, -c.semidims, c.semidims)
        return new_q, new_v
    if new_v is not out[1]:  # a limit made a new tensor
        out[1].copy_(new_v)
    new_q = torch.mul(out[1], c.sub_dt, out=out[0]).add_(q)
    if c.semidims is not None:
        new_q.clamp_(-c.semidims, c.semidims)
    return out
