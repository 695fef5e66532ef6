"""Random numbers for sensor noise, computed inside the step from (seed, step, element) alone.

Training's observation noise needs tens of thousands of random numbers per
step (one per lidar ray, agent and env, and as many again for the dropout).
Drawn from a torch generator they cost a pass of their own before the
noise's kernel, and on the CPU the generator's one thread sets their pace.
Here each number is a hash of its element's index, the step's counter and
the seed: plain integer arithmetic that the compiler fuses into the kernel
that uses the numbers, and that gives the same bits eagerly and compiled (no
float function is involved before the final scaling), on every device.

The hash is the 32-bit "lowbias32" integer finaliser (xor-shift, multiply,
xor-shift, multiply, xor-shift; constants from Chris Wellons' hash
prospector), on int32 tensors: products wrap modulo 2^32 as torch's and the
compiler's vector code do, and each right shift is masked to its bits, so
the sign of an int32 never leaks in. A test checks the bits against the
same hash in Python integers.

One hash per lidar ray serves both the ray's noise and its dropout: three
of its bytes, summed, centred and scaled to unit variance, are a normal
error (Irwin-Hall with three terms of 256 levels: mean and standard
deviation exact, tails ending at 3 sigma, which a sensor model can take);
the fourth byte is the dropout's uniform (a drop probability counts in
steps of 1/256). The position and velocity errors take one hash each.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["hash32", "hashes", "stream_key", "normals", "uniforms"]

#: lowbias32's multipliers, as the int32 values of their bits
_MULTIPLIERS = (0x7FEB352D, 0x846CA68B - (1 << 32))
#: three bytes' sum: mean 3 * 255 / 2 and variance 3 * (256^2 - 1) / 12
_BYTE_SUM_MEAN = 382.5
_BYTE_SUM_INV_STD = 1.0 / math.sqrt(3 * (256 ** 2 - 1) / 12)
#: the steps' keys are spread by this odd constant (2^32 / golden ratio), as an int32
_STEP_STRIDE = 0x9E3779B9 - (1 << 32)


def _shifted(x: Tensor, bits: int) -> Tensor:
    """``x >> bits`` as if ``x`` were unsigned (int32's right shift copies the sign bit)."""
    return (x >> bits) & ((1 << (32 - bits)) - 1)


def hash32(x: Tensor) -> Tensor:
    """A well-mixed 32-bit hash of each element of ``x`` (int32; the bits are what count)."""
    x = x ^ _shifted(x, 16)
    x = x * _MULTIPLIERS[0]
    x = x ^ _shifted(x, 15)
    x = x * _MULTIPLIERS[1]
    return x ^ _shifted(x, 16)


def stream_key(seed_key: Tensor, step: Tensor) -> Tensor:
    """The 0-d int32 key of one step's numbers, from the seed's key and the step counter (0-d int32 tensors)."""
    return hash32(seed_key + step * _STEP_STRIDE)


def hashes(key: Tensor, shape, offset: int = 0) -> Tensor:
    """The step's hashes number ``offset`` onwards, int32 of ``shape`` (ranges that do not overlap give
    numbers that do not repeat)."""
    count = math.prod(shape)
    index = torch.arange(offset, offset + count, dtype=torch.int32, device=key.device).view(shape)
    return hash32(index + key)


def normals(h: Tensor, dtype: torch.dtype) -> Tensor:
    """Standard normal errors (Irwin-Hall, see the module) from hashes ``h``: their three low bytes."""
    byte_sum = (h & 0xFF) + ((h >> 8) & 0xFF) + ((h >> 16) & 0xFF)  # the byte masks drop the sign's copies
    return (byte_sum.to(dtype) - _BYTE_SUM_MEAN) * _BYTE_SUM_INV_STD


def uniforms(h: Tensor, dtype: torch.dtype) -> Tensor:
    """Uniforms in (0, 1) from hashes ``h``: their high byte, in 256 steps."""
    return (_shifted(h, 24).to(dtype) + 0.5) * (1.0 / 256.0)
