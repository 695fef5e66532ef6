"""Per-coordinate constants of the step, computed once per world layout (tables) and step parameters.

Rows of every ``[3, N, 1]`` column are (x, y, angle): mass for the first two,
moment of inertia for the angle, so one elementwise op integrates all three
coordinates. Held entities (landmarks, agents that cannot move or turn) stay
still; how, is chosen from these constants and the batch size by
:mod:`vmas_ros.simulator.physics.integrator`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Optional, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.layout import split_xy_stacked
from vmas_ros.simulator.masks import zero_like
from vmas_ros.simulator.thresholds import GEMM_SCATTER_MAX_CELLS
from vmas_ros.simulator.physics.scales import dynamics_columns
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import WorldTables

__all__ = ["StepConstants", "step_constants"]


@dataclass
class StepConstants:
    """What :func:`vmas_ros.simulator.physics.pipeline.step` needs besides the state, as tensors."""

    key: Tuple  # (sub_dt, x_semidim, y_semidim): the step parameters these were built for
    sub_dt: float  # dt / substeps
    keep: Tensor  # [N, 1] 1 - drag, applied on the first substep ([N, B] with per-env scales, as the next three)
    mass: Tensor  # [3, N, 1] mass, mass, moment of inertia
    friction_cap: Tensor  # [3, N, 1] linear friction * mass (x, y), angular friction * inertia
    mass_over_dt: Tensor  # [3, N, 1] the force that stops each coordinate within one substep
    gravity: Tensor  # [3, N, 1 or B] gravity force (x, y), no torque
    max_speed: Tensor  # [N, 1], inf when unlimited
    finite_max_speed: Tensor  # [N, 1], 0 where unlimited (never multiplies an inf)
    v_range: Tensor  # [3, N, 1] per-coordinate velocity bound (x, y), inf for the angle
    semidims: Optional[Tensor]  # [3, 1, 1] position bounds (x, y, inf for the angle); None: unbounded
    limits_speed: bool  # some finite max_speed
    limits_velocity: bool  # some finite v_range
    free: Tensor  # [3, N, 1] bool: the coordinate moves (movable for x, y; rotatable for the angle)
    all_free: bool  # no entity is held in any coordinate
    held_rows: Tensor  # [H] long: held rows of the flattened [3 * N, B] state (coordinate-major)
    free_span: Optional[Tuple[int, int]]  # (lo, hi) when entities lo:hi are free and the rest one held block
    free_block: Optional["StepConstants"]  # these constants for entities lo:hi only


def step_constants(tables: WorldTables, params: StepParams) -> StepConstants:
    """The step's constants for ``tables`` and ``params``, cached in ``tables.step_constants``.

    Also builds the tables' lazily made helpers (incidence matrices, contact
    distances, the shared zero): filled inside a compiled step, such a cache
    breaks its graph.
    """
    sub_dt = params.dt / params.substeps
    key = (sub_dt, params.x_semidim, params.y_semidim)
    cached = tables.step_constants
    if cached is not None and cached.key == key:
        return cached
    col = lambda t: t[..., 0]  # noqa: E731  [N, 1, 1] -> [N, 1]
    per_coord = lambda lin, ang: torch.stack([lin, lin, ang])  # noqa: E731
    keep, coord_mass, friction_cap = dynamics_columns(tables)
    mass = col(tables.mass)
    free = per_coord(col(tables.movable), col(tables.rotatable))
    max_speed, v_range = col(tables.max_speed), col(tables.v_range)
    inf = float("inf")
    bounds = [inf if b is None else b for b in (params.x_semidim, params.y_semidim)] + [inf]
    span = _free_span(free)
    constants = StepConstants(
        key=key, sub_dt=sub_dt,
        keep=keep, mass=coord_mass, friction_cap=friction_cap, mass_over_dt=coord_mass / sub_dt,
        gravity=torch.cat([split_xy_stacked(tables.gravity_force.contiguous()),
                           torch.zeros_like(tables.gravity_force[..., 0]).unsqueeze(0)]),
        max_speed=max_speed, finite_max_speed=torch.where(torch.isfinite(max_speed), max_speed, 0.0),
        v_range=torch.stack([v_range, v_range, torch.full_like(v_range, inf)]),
        semidims=(None if params.x_semidim is None and params.y_semidim is None
                  else torch.tensor(bounds, dtype=mass.dtype, device=mass.device).reshape(3, 1, 1)),
        limits_speed=tables.limits_speed, limits_velocity=tables.limits_velocity,
        free=free, all_free=bool(free.all()),
        held_rows=(~free[..., 0]).flatten().nonzero()[:, 0],
        free_span=span, free_block=None,
    )
    if span is not None:
        constants.free_block = _block(constants, *span)
    _build_table_helpers(tables, mass)
    tables.step_constants = constants
    return constants


def _free_span(free: Tensor) -> Optional[Tuple[int, int]]:
    """``(lo, hi)`` when entities ``lo:hi`` are free in all three coordinates and every other
    entity is held in all three, with the held ones one block at an end; else None (also when all are free)."""
    per_entity = free[..., 0]  # [3, N]
    whole = per_entity.all(dim=0)
    if not bool((per_entity == whole).all()) or bool(whole.all()) or not bool(whole.any()):
        return None
    rows = whole.nonzero()[:, 0].tolist()
    lo, hi = rows[0], rows[-1] + 1
    if hi - lo != len(rows) or (lo != 0 and hi != whole.numel()):
        return None
    return lo, hi


def _block(c: StepConstants, lo: int, hi: int) -> StepConstants:
    """The constants the integrator reads, for entities ``lo:hi`` only."""
    return dataclasses.replace(
        c, keep=c.keep[lo:hi], max_speed=c.max_speed[lo:hi], finite_max_speed=c.finite_max_speed[lo:hi],
        mass=c.mass[:, lo:hi], v_range=c.v_range[:, lo:hi], free_block=None,
    )


def _build_table_helpers(tables: WorldTables, like: Tensor) -> None:
    n_entities = tables.n_entities
    zero_like(like)
    for table in tables.pairs + ([tables.joints] if tables.joints is not None else []):
        if n_entities * len(table.index_a) <= GEMM_SCATTER_MAX_CELLS:  # never used above: a dense matrix too big
            table.incidence_ab(n_entities, like.dtype)
            table.incidence_opposite(n_entities, like.dtype)
        table.index_ab
        if table in tables.pairs and table.kind == ("sphere", "sphere"):
            table.contact_distance
