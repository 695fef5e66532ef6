"""Conversions between vector ``[..., 2]`` tensors and planar ``x``, ``y`` components.

The public state of an entity is a ``[B, 2]`` vector (VMAS's API), while the
physics step runs on contiguous planar components (see
:mod:`vmas_ros.simulator.physics`). Converting between the two is a strided
copy, and on the CPU build we ship against the obvious ways,
``torch.stack([x, y], -1)`` and ``v[..., 0].contiguous()``, are far slower per
element than arithmetic. Two tricks do the same copies far faster and bit for
bit:

* :func:`join_xy` packs ``x + iy`` into a complex tensor and views it as
  ``[..., 2]`` reals (complex numbers are stored as (real, imaginary) pairs);
* :func:`split_xy` views each float32 ``(x, y)`` pair as one 64-bit integer
  and takes its low and high 32 bits (little-endian storage: ``x`` is the low
  half), which are again floats when viewed as such.

Both move bits only, so NaN payloads, signed zeros and subnormals survive.
Other dtypes fall back to plain slicing.
"""
from __future__ import annotations

import sys
from typing import Sequence, Tuple

import torch
from torch import Tensor

from vmas_ros.simulator.tracing import tracing
_LITTLE_ENDIAN = sys.byteorder == "little"


def _bit_trick(vectors: Tensor) -> bool:
    """Whether the integer view may be used: float32, little-endian, contiguous, and no gradient to keep
    (integer views cut the autograd graph; differentiable envs take the plain, slower copy)."""
    return (vectors.dtype == torch.float32 and _LITTLE_ENDIAN and vectors.is_contiguous()
            and not (vectors.requires_grad and torch.is_grad_enabled()))


def split_xy(vectors: Tensor) -> Tuple[Tensor, Tensor]:
    """``[..., 2]`` -> contiguous ``x``, ``y`` of shape ``[...]`` (bit-exact copies)."""
    if _bit_trick(vectors):
        pairs = vectors.view(torch.int64).squeeze(-1)  # one (x, y) pair per int64
        x = pairs.to(torch.int32).view(torch.float32)  # low 32 bits
        y = (pairs >> 32).to(torch.int32).view(torch.float32)  # high 32 bits
        return x, y
    x, y = vectors.unbind(-1)
    return x.contiguous(), y.contiguous()


def split_xy_stacked(vectors: Tensor) -> Tensor:
    """``[..., 2]`` -> contiguous ``[2, ...]`` (``x`` then ``y``; bit-exact copies)."""
    if _bit_trick(vectors):
        pairs = vectors.view(torch.int64).squeeze(-1)
        return torch.stack([pairs, pairs >> 32]).to(torch.int32).view(torch.float32)
    return torch.stack(vectors.unbind(-1))


def split_xy_into(vectors: Tensor, xy: Tensor) -> None:
    """Write the components of ``[..., 2]`` ``vectors`` into ``xy`` ``[2, ...]`` (x then y), bit-exactly.

    :func:`split_xy_stacked` without its output: the caller's rows are
    filled directly (the 32-bit halves of each 64-bit pair are copied into
    integer views of them), so no intermediate of the whole batch is kept.
    """
    if _bit_trick(vectors) and xy.dtype == torch.float32 and xy[0].is_contiguous() and xy[1].is_contiguous():
        pairs = vectors.view(torch.int64).squeeze(-1)
        xy[0].view(torch.int32).copy_(pairs)  # int64 -> int32 keeps the low 32 bits: x
        xy[1].view(torch.int32).copy_(pairs >> 32)
        return
    xy.copy_(vectors.movedim(-1, 0))  # one copy: autograd sees a single write


def stack_into(vectors: Sequence[Tensor], rows: Tensor) -> None:
    """Write ``K`` per-entity ``[B, D]`` tensors into the rows ``[D, K, B]`` of a planar state, in one call.

    ``stack(out=)`` into a permuted view of the destination: no stacked
    temporary and no split, far faster at large batches than a stack and a
    bit-exact split. ``out=`` refuses tensors that need a gradient, so only
    without one.
    """
    torch.stack(list(vectors), out=rows.permute(1, 2, 0))


def join_xy(x: Tensor, y: Tensor) -> Tensor:
    """Contiguous ``[..., 2]`` vectors from components ``x``, ``y`` (bit-exact copies).

    Under ``torch.compile`` a plain stack, which the compiler fuses into its loops.
    """
    if tracing():
        return torch.stack([x, y], dim=-1)
    if x.dtype in (torch.float32, torch.float64) and y.dtype == x.dtype and x.shape == y.shape:
        return torch.view_as_real(torch.complex(x, y))
    return torch.stack([x, y], dim=-1)


def cat_columns(parts: Sequence[Tensor], leading: Sequence[int]) -> Tensor:
    """``torch.cat`` along the last dim of ``parts``, each broadcast to ``(*leading, its width)`` (exact copies).

    For observation layouts built from blocks that share a prefix (an agent's
    own state, then one block per package). Eagerly each part is written into
    its columns of one new tensor, with no expanded copies; under
    ``torch.compile`` it is one concatenation of expanded views, which the
    compiler fuses (strided column writes compile to a scalar loop).
    """
    leading = tuple(leading)
    if tracing():
        return torch.cat([part.expand(*leading, part.shape[-1]) for part in parts], dim=-1)
    out = parts[0].new_empty(*leading, sum(part.shape[-1] for part in parts))
    column = 0
    for part in parts:
        width = part.shape[-1]
        out[..., column:column + width] = part
        column += width
    return out


def as_pairs(vectors: Tensor) -> Tensor:
    """``[..., 2]`` float vectors viewed as ``[...]`` complex numbers, one per ``(x, y)`` pair (no copy).

    For copies that move whole vectors, such as transposing ``[agents, rows,
    batch, 2]`` into ``[agents, batch, rows, 2]`` to lay out observations: a
    strided copy of 8-byte pairs runs far faster than the same copy of
    4-byte floats with a trailing dim of 2, and moves the same bits. Needs a
    contiguous last dim and even strides/offset (true of the state stacks).
    Complex pairs (from :func:`complex_pairs`) are returned as they are.
    """
    return vectors if vectors.is_complex() else torch.view_as_complex(vectors)


def complex_pairs(x: Tensor, y: Tensor) -> Tensor:
    """Components ``x``, ``y`` as ``(x, y)`` pairs to read back with :func:`as_pairs`.

    Eagerly, complex numbers straight from ``torch.complex``: a tensor that is
    not a view of another costs less per indexing and per op than viewing
    ``[..., 2]`` vectors as complex numbers. Under ``torch.compile``, ``[..., 2]``
    vectors (:func:`join_xy`): the compiler fuses a stack into its loops and
    would leave complex numbers to ATen.
    """
    if tracing():
        return join_xy(x, y)
    return torch.complex(x, y)
