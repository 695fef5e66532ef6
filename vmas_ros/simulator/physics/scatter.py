"""Adding per-pair forces ``[C, P, B]`` onto the entities' force ``[C, N, B]``.

Three equivalent ways, picked by size (see :mod:`vmas_ros.simulator.thresholds`):
``index_add_`` in pair order (VMAS's summation order: kernels that compute as
VMAS does stay bit-identical to it), the same on a transposed view (few envs),
or one batched GEMM against a dense incidence matrix cached on the pair table
(compiled steps, few envs, multi-threaded runs). Under ``torch.compile``,
``index_add_`` lowers to a serial loop of atomic adds, so compiled steps use
the GEMM, or :func:`scatter_rows`, an op the compiler leaves to ATen.
"""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator.thresholds import (
    GEMM_SCATTER_MAX_CELLS, GEMM_SCATTER_MIN_PAIRS, SCATTER_TRANSPOSE_BELOW, SUMMED_SCATTER_MAX_ELEMENTS,
)
from vmas_ros.simulator.tracing import tracing

__all__ = ["add_pairs", "add_pairs_opposite", "scatter_by_gemm", "scatter_rows"]


def scatter_by_gemm(n_entities: int, n_pairs: int, batch: int) -> bool:
    """Whether per-pair forces are added onto entities by one batched GEMM with a dense incidence matrix.

    ``index_add_`` pays per index at a few envs, runs on one thread, and under
    ``torch.compile`` lowers to a serial scatter of atomic adds; a GEMM is one
    vectorised, multi-threaded call everywhere. With one thread and many envs
    ``index_add_`` is faster, and with a few pairs over many envs the two run
    level. The GEMM sums in its own order, so kernels that promise VMAS's
    summation order use it only when compiled (see :func:`add_pairs`).
    """
    if n_entities * n_pairs > GEMM_SCATTER_MAX_CELLS:
        return False
    return (tracing() or batch < SCATTER_TRANSPOSE_BELOW
            or (n_pairs >= GEMM_SCATTER_MIN_PAIRS and torch.get_num_threads() > 1))


def add_pairs(force: Tensor, table, on_a: Tensor, on_b: Tensor) -> None:
    """Add per-pair values ``[C, P, B]`` onto ``force`` ``[C, N, B]`` in place, in pair order (a0, b0, a1, b1, ...).

    The same summation order as VMAS, so kernels that compute their forces as
    VMAS does (joints, boxes, lines) stay bit-identical to it: stiff joints
    amplify a one-ulp difference within a few steps. Compiled steps promise
    float rounding only, and scatter with a GEMM.
    """
    n_entities, n_pairs = force.shape[1], on_a.shape[1]
    if tracing() and n_entities * n_pairs <= GEMM_SCATTER_MAX_CELLS:
        first, second = table.incidence_ab(n_entities, force.dtype)
        _add_product(force, first, on_a)
        _add_product(force, second, on_b)
        return
    values = torch.stack([on_a, on_b], dim=2).flatten(1, 2)
    if tracing():  # too many (entity, pair) cells for a dense matrix
        scatter_rows(force, table.index_ab, values)
    elif force.shape[-1] < SCATTER_TRANSPOSE_BELOW:
        # few envs: along dim 0 of the transposed view, index_add_ runs as one loop
        force.transpose(0, 1).index_add_(0, table.index_ab, values.transpose(0, 1))
    else:
        force.index_add_(1, table.index_ab, values)


def add_pairs_opposite(force: Tensor, table, on_a: Tensor) -> None:
    """Add ``on_a`` ``[C, P, B]`` onto the first members and ``-on_a`` onto the second, in place.

    No ``[C, 2P, B]`` stack or negated copy: one GEMM (see
    :func:`scatter_by_gemm`) or two scatters, in an order VMAS does not use,
    so only for kernels that do not promise bit parity (see :func:`add_pairs`).
    """
    n_entities, n_pairs, batch = force.shape[1], on_a.shape[1], force.shape[2]
    if scatter_by_gemm(n_entities, n_pairs, batch):
        _add_product(force, table.incidence_opposite(n_entities, force.dtype), on_a)
    elif tracing():  # too many (entity, pair) cells for a dense matrix
        scatter_rows(force, table.index_a, on_a)
        scatter_rows(force, table.index_b, on_a.neg())
    elif batch < SCATTER_TRANSPOSE_BELOW:
        target, values = force.transpose(0, 1), on_a.transpose(0, 1)
        target.index_add_(0, table.index_a, values)
        target.index_add_(0, table.index_b, values.neg())  # alpha=-1 takes a slow path on this view
    else:
        force.index_add_(1, table.index_a, on_a)
        force.index_add_(1, table.index_b, on_a, alpha=-1)


def _add_product(force: Tensor, incidence: Tensor, values: Tensor) -> None:
    """``force += incidence @ values`` in place: ``force`` ``[C, N, B]``, ``incidence`` ``[N, P]``, ``values``
    ``[C, P, B]``. A batched GEMM; in a compiled step over few elements, a product summed over the pairs,
    which the compiler fuses into its own loops (``SUMMED_SCATTER_MAX_ELEMENTS``)."""
    if tracing() and incidence.numel() * values.shape[-1] <= SUMMED_SCATTER_MAX_ELEMENTS:
        force.add_((incidence.unsqueeze(-1) * values.unsqueeze(1)).sum(dim=2))  # [C, N, P, B] summed over P
    else:
        force.baddbmm_(incidence.expand(force.shape[0], -1, -1), values)


@torch.library.custom_op("vmas_ros::scatter_rows", mutates_args=("target",))
def scatter_rows(target: Tensor, index: Tensor, values: Tensor) -> None:
    """``target.index_add_(1, index, values)`` as an op the compiler leaves to ATen.

    For compiled steps with more pairs than a dense incidence matrix can hold:
    inductor lowers ``index_add_`` to a serial loop of atomic adds, while the
    eager kernel is one vectorised pass (transposed at a few envs).
    """
    if target.shape[-1] < SCATTER_TRANSPOSE_BELOW:
        target.transpose(0, 1).index_add_(0, index, values.transpose(0, 1))
    else:
        target.index_add_(1, index, values)


@scatter_rows.register_fake
def _(target: Tensor, index: Tensor, values: Tensor) -> None:
    return None
