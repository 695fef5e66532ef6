"""The observation noise's random numbers (vmas_ros/envs/sensor_noise.py): the hash's bits, checked against
the same hash in Python integers, and the distributions made from them."""
from __future__ import annotations

import math

import pytest
import torch

from vmas_ros.envs import sensor_noise

MASK = 0xFFFFFFFF


def _reference_hash(x: int) -> int:
    """lowbias32 in unbounded Python integers, reduced modulo 2^32 at each product."""
    x &= MASK
    x ^= x >> 16
    x = (x * 0x7FEB352D) & MASK
    x ^= x >> 15
    x = (x * 0x846CA68B) & MASK
    return x ^ (x >> 16)


def _int32(value: int) -> int:
    value &= MASK
    return value - (1 << 32) if value >= 1 << 31 else value


def test_the_hash_gives_the_reference_bits_on_every_device(device):
    inputs = [0, 1, 2, 7919, 123_456_789, (1 << 31) - 1, 1 << 31, MASK, 0xDEADBEEF]
    got = sensor_noise.hash32(torch.tensor([_int32(v) for v in inputs], dtype=torch.int32, device=device))
    assert [v & MASK for v in got.tolist()] == [_reference_hash(v) for v in inputs]
    key = torch.tensor(_int32(0xCAFEF00D), dtype=torch.int32, device=device)
    shown = sensor_noise.hashes(key, (2, 3), offset=5)
    assert [v & MASK for v in shown.flatten().tolist()] == [_reference_hash(0xCAFEF00D + 5 + i) for i in range(6)]


def test_the_compiled_numbers_are_the_eager_ones_bit_for_bit():
    def noise(key, step):
        h = sensor_noise.hashes(sensor_noise.stream_key(key, step), (64, 100))
        return sensor_noise.normals(h, torch.float32), sensor_noise.uniforms(h, torch.float32)

    key, step = torch.tensor(12345, dtype=torch.int32), torch.tensor(3, dtype=torch.int32)
    compiled = torch.compile(noise, dynamic=False)
    for eager_part, compiled_part in zip(noise(key, step), compiled(key, step)):
        assert torch.equal(eager_part, compiled_part)


def test_normals_have_unit_variance_and_uniforms_fill_the_unit_interval(device):
    h = sensor_noise.hashes(torch.tensor(42, dtype=torch.int32, device=device), (400_000,))
    normal, uniform = sensor_noise.normals(h, torch.float64), sensor_noise.uniforms(h, torch.float64)
    assert abs(float(normal.mean())) < 5 / math.sqrt(normal.numel())
    assert float(normal.std()) == pytest.approx(1.0, abs=0.01)
    assert float(normal.abs().max()) <= 3.0  # three bytes: the tails end at 3 sigma
    assert float((normal.abs() < 1).double().mean()) == pytest.approx(0.683, abs=0.02)  # a Gaussian's share
    assert 0 < float(uniform.min()) < 0.01 and 0.99 < float(uniform.max()) < 1
    assert float(uniform.mean()) == pytest.approx(0.5, abs=0.005)
    # the normal's bytes and the uniform's byte are apart: no correlation
    assert abs(float(torch.corrcoef(torch.stack([normal, uniform]))[0, 1])) < 0.01


def test_each_step_and_seed_gives_other_numbers_and_a_step_repeats_its_own(device):
    def numbers(seed: int, step: int):
        key = sensor_noise.stream_key(sensor_noise.hash32(torch.tensor(seed, dtype=torch.int32, device=device)),
                                      torch.tensor(step, dtype=torch.int32, device=device))
        return sensor_noise.hashes(key, (1000,))

    assert torch.equal(numbers(1, 5), numbers(1, 5))
    for other in (numbers(1, 6), numbers(2, 5)):
        assert float((other == numbers(1, 5)).double().mean()) < 0.01
    # neighbouring steps are not shifted copies of each other
    assert float((numbers(1, 6)[:-1] == numbers(1, 5)[1:]).double().mean()) < 0.01
