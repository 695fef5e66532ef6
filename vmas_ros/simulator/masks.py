"""Float 0/1 masks and exact selection, the engine's alternative to bool tensors and ``torch.where``.

On the CPU build we ship against, comparisons that produce bool tensors and
``torch.where`` run far slower than arithmetic, so the physics and the ray
casts compare into a float ``out=`` tensor and apply the mask by
multiplication. For finite operands ``a * 1 = a`` and ``a * 0 + b = b``
exactly, so the results are bit-identical to the bool versions.
"""
from __future__ import annotations

from typing import Tuple

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.tracing import tracing

__all__ = ["mask_eq", "mask_ge", "mask_gt", "mask_le", "mask_lt", "mask_ne", "select", "zero_like"]


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


def select(mask: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """``where(mask, a, b)`` for a float 0/1 ``mask`` and finite ``a``, ``b`` (exact)."""
    return a * mask + b * (1 - mask)


def zero_like(like: Tensor) -> Tensor:
    """A cached 0-dim zero on ``like``'s device and dtype (one allocation fewer per kernel call)."""
    key = (like.device, like.dtype)
    zero = _ZEROS.get(key)
    if zero is None:
        zero = _ZEROS[key] = torch.zeros((), device=like.device, dtype=like.dtype)
    return zero


_ZEROS: dict = {}


def _broadcast_shape(a: Tensor, b) -> Tuple[int, ...]:
    if not isinstance(b, Tensor) or b.shape == a.shape:
        return tuple(a.shape)
    if tracing():  # the plain-Python loop breaks the compiled graph
        return tuple(torch.broadcast_shapes(a.shape, b.shape))
    return geo.broadcast_shape(a.shape, b.shape)
