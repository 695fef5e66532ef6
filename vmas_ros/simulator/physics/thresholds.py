"""Batch and problem sizes at which the physics switches between equivalent ways of computing.

Each switch picks between code paths that give the same results (to float
rounding, or bit for bit where noted); only their speed or memory differs.
The values were set by measuring both sides of each switch with the
project's benchmark commands (docs/bench/); the reasons are kept here.
"""
from __future__ import annotations

#: Below this many envs, pair forces are scattered along dim 0 of a transposed view: CPU
#: ``index_add_`` along an inner dim pays per index, which dominates when each index moves
#: only a few envs. Same order, same sums.
SCATTER_TRANSPOSE_BELOW = 16

#: Pair forces may be scattered with one GEMM against a dense ``[N, P]`` incidence matrix up to
#: this many (entity, pair) cells; above, the matrix would cost more memory than it saves time.
GEMM_SCATTER_MAX_CELLS = 1 << 14

#: Eager steps over many envs scatter by GEMM only from this many pairs of one kernel: with
#: fewer, ``index_add_`` runs level with it and the BLAS kernel is not worth its resident code.
GEMM_SCATTER_MIN_PAIRS = 8

#: Up to this many state elements, held entities are kept still with one ``torch.where`` (the
#: per-call cost dominates); above, by copying their rows back or integrating only the free
#: block (``torch.where`` is slow per element on the CPU). Also where the action input switches
#: from one strided copy to per-component copies.
SMALL_BATCH_ELEMENTS = 8192
