"""Tests for vmas_ros.simulator.raycast: hand-computed cases + VMAS oracle."""
import math

import pytest
import torch

from vmas.simulator.core import World

from vmas_ros.simulator.raycast import ray_box, ray_segment, ray_sphere

devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
ATOL = 1e-5
MAX = 8.0
B, E, A = 256, 5, 16  # oracle batch: envs x entities x ray angles


@pytest.fixture(params=devices)
def device(request):
    return torch.device(request.param)


@pytest.fixture
def gen():
    return torch.Generator().manual_seed(0)


def T(x, device, dtype=torch.float32):
    return torch.tensor(x, dtype=dtype, device=device)


def close(a, b, atol=ATOL):
    torch.testing.assert_close(a, b, atol=atol, rtol=0)


def rand(shape, lo, hi, device, gen):
    return torch.rand(shape, generator=gen).to(device) * (hi - lo) + lo


# ----------------------------------------------------------------- analytic


def test_sphere_analytic(device):
    origin = T([[-3.0, 0.0], [-3.0, 1.0], [-3.0, 0.6], [-3.0, 0.0], [-0.5, 0.0], [-0.5, 0.0], [0.0, 0.0], [-20.0, 0.0]], device)
    angle = T([0.0, 0.0, 0.0, math.pi, 0.0, math.pi, 0.0, 0.0], device)
    d = ray_sphere(origin, angle, T([0.0, 0.0], device), 1.0, MAX)
    # head-on, grazing (strict miss), chord, behind, inside with centre in front (negative),
    # inside with centre behind, origin at the centre, hit beyond max_range (not clamped)
    close(d, T([2.0, MAX, 2.2, MAX, -0.5, MAX, MAX, 19.0], device))
    assert torch.isfinite(d).all()


def test_box_analytic(device):
    c = T([0.0, 0.0], device)
    origin = T([[-5.0, 0.0], [0.0, -5.0], [-5.0, 3.0], [-5.0, 0.0], [0.0, 0.0], [-5.0, 0.5], [-5.0, 0.499]], device)
    angle = T([0.0, math.pi / 2, 0.0, math.pi, 0.0, 0.0, 0.0], device)
    # L=2 along x, W=1 along y: head-on x, head-on y, miss, behind, inside, exactly along
    # the top side (direction y is exactly 0: miss, no NaN), just inside the top side
    d = ray_box(origin, angle, c, T(0.0, device), 2.0, 1.0, MAX)
    close(d, T([4.0, 4.5, MAX, MAX, MAX, MAX, 4.0], device))
    # rotated by 90 degrees: x extent is now the width
    close(ray_box(T([-5.0, 0.0], device), T(0.0, device), c, T(math.pi / 2, device), 2.0, 1.0, MAX), T(4.5, device))
    # rotated by 45 degrees: a diamond whose vertex is at sqrt(2)
    d = ray_box(T([-5.0, 0.0], device), T(0.0, device), c, T(math.pi / 4, device), 2.0, 2.0, MAX)
    close(d, T(5.0 - math.sqrt(2), device))
    # off-centre box, ray at 45 degrees hitting its corner region
    d = ray_box(T([0.0, 0.0], device), T(math.pi / 4, device), T([3.0, 3.0], device), T(0.0, device), 2.0, 2.0, MAX)
    close(d, T(2 * math.sqrt(2), device))


def test_segment_analytic(device):
    c = T([0.0, 0.0], device)
    origin = T([[-3.0, 0.0], [-3.0, 1.0], [-3.0, 1.001], [-3.0, 0.0], [2.0, -2.0]], device)
    angle = T([0.0, 0.0, 0.0, math.pi, 3 * math.pi / 4], device)
    # vertical segment of length 2: head-on, exactly at its end, just past the end, behind,
    # diagonal hit at (0, 0)
    d = ray_segment(origin, angle, c, T(math.pi / 2, device), 2.0, MAX)
    close(d, T([3.0, 3.0, MAX, MAX, 2 * math.sqrt(2)], device))
    # horizontal segment: collinear and parallel offset rays never hit, origin on the
    # segment gives distance 0, a ray through the segment's centre from below hits
    origin = T([[-3.0, 0.0], [-3.0, 0.5], [0.5, 0.0], [0.0, -2.0]], device)
    angle = T([0.0, 0.0, math.pi / 2, math.pi / 2], device)
    d = ray_segment(origin, angle, c, T(0.0, device), 2.0, MAX)
    close(d, T([MAX, MAX, 0.0, 2.0], device))


def test_broadcast_lidar_shapes_dtype(device, gen):
    dt = torch.float64
    Bn, R, En = 3, 7, 4
    origin = rand((Bn, 1, 1, 2), -1, 1, device, gen).to(dt)
    angle = torch.linspace(-math.pi, math.pi, R, dtype=dt, device=device).view(1, R, 1).expand(Bn, R, 1)
    center = rand((Bn, 1, En, 2), -3, 3, device, gen).to(dt)
    rot = rand((Bn, 1, En), -3, 3, device, gen).to(dt)
    size = rand((Bn, 1, En), 0.2, 1.0, device, gen).to(dt)
    for out in (
        ray_sphere(origin, angle, center, size, MAX),
        ray_box(origin, angle, center, rot, size, 0.5, MAX),
        ray_segment(origin, angle, center, rot, size, MAX),
    ):
        assert out.shape == (Bn, R, En) and out.dtype == dt and out.device.type == device.type
        assert torch.isfinite(out).all()
    # per-element evaluation agrees with the broadcast one
    full = ray_box(origin, angle, center, rot, size, 0.5, MAX)
    flat = ray_box(
        origin.expand(Bn, R, En, 2).reshape(-1, 2), angle.expand(Bn, R, En).reshape(-1),
        center.expand(Bn, R, En, 2).reshape(-1, 2), rot.expand(Bn, R, En).reshape(-1),
        size.expand(Bn, R, En).reshape(-1), T(0.5, device, dt), T(MAX, device, dt),
    )
    close(full.reshape(-1), flat)


def test_gradients_finite(device):
    origin = T([[-5.0, 1.0], [-5.0, 0.0], [0.0, 0.0]], device, torch.float64).requires_grad_()
    angle = T([0.0, math.pi / 2, 0.0], device, torch.float64)
    c = T([0.0, 0.0], device, torch.float64)
    zero = T(0.0, device, torch.float64)
    total = (
        ray_box(origin, angle, c, zero, 2.0, 2.0, MAX).sum()
        + ray_segment(origin, angle, c, zero, 2.0, MAX).sum()
        + ray_sphere(origin, angle, c, 1.0, MAX).sum()
    )
    total.backward()
    assert torch.isfinite(origin.grad).all()


# ------------------------------------------------------------ VMAS oracle


def _rays(device, gen):
    origin = rand((B, 2), -2, 2, device, gen)
    angles = rand((B, A), -math.pi, math.pi, device, gen)
    return origin, angles


def _mine_args(origin, angles):
    """[B, 2] / [B, A] rays laid out against [B, E, 1] entities -> [B, E, A]."""
    return origin[:, None, None, :], angles[:, None, :]


def _check(mine, ref):
    hits = ref < MAX
    assert 0.05 < hits.float().mean().item() < 0.95  # both outcomes exercised
    assert torch.equal(mine < MAX, hits)
    close(mine, ref)


def test_oracle_sphere(device, gen):
    world = World(batch_dim=B, device=device)
    origin, angles = _rays(device, gen)
    pos, radius = rand((B, E, 2), -3, 3, device, gen), rand((B, E), 0.1, 1.5, device, gen)
    ref = world._cast_rays_to_sphere(pos, radius, origin, angles, MAX)
    mine = ray_sphere(*_mine_args(origin, angles), pos[:, :, None], radius[:, :, None], MAX)
    assert (ref < 0).any()  # origins inside a sphere are covered
    _check(mine, ref)


def test_oracle_box(device, gen):
    world = World(batch_dim=B, device=device)
    origin, angles = _rays(device, gen)
    pos, rot = rand((B, E, 2), -3, 3, device, gen), rand((B, E), -math.pi, math.pi, device, gen)
    length, width = rand((B, E), 0.1, 2.0, device, gen), rand((B, E), 0.1, 2.0, device, gen)
    ref = world._cast_rays_to_box(pos, rot, length, width, origin, angles, MAX)
    mine = ray_box(*_mine_args(origin, angles), pos[:, :, None], rot[:, :, None], length[:, :, None], width[:, :, None], MAX)
    _check(mine, ref)


def test_oracle_box_axis_aligned(device, gen):
    """Axis-aligned rays and boxes on a grid hit slab planes and zero direction components."""
    world = World(batch_dim=B, device=device)
    origin = torch.round(rand((B, 2), -2, 2, device, gen) * 2) / 2
    angles = torch.randint(0, 4, (B, A), generator=gen).to(device) * (math.pi / 2)
    pos = torch.round(rand((B, E, 2), -3, 3, device, gen) * 2) / 2
    rot = torch.zeros(B, E, device=device)
    length = torch.randint(1, 5, (B, E), generator=gen).to(device).float() / 2
    width = torch.randint(1, 5, (B, E), generator=gen).to(device).float() / 2
    ref = world._cast_rays_to_box(pos, rot, length, width, origin, angles, MAX)
    mine = ray_box(*_mine_args(origin, angles), pos[:, :, None], rot[:, :, None], length[:, :, None], width[:, :, None], MAX)
    _check(mine, ref)


def test_oracle_segment(device, gen):
    world = World(batch_dim=B, device=device)
    origin, angles = _rays(device, gen)
    pos, rot = rand((B, E, 2), -3, 3, device, gen), rand((B, E), -math.pi, math.pi, device, gen)
    length = rand((B, E), 0.1, 3.0, device, gen)
    ref = world._cast_rays_to_line(pos, rot, length, origin, angles, MAX)
    mine = ray_segment(*_mine_args(origin, angles), pos[:, :, None], rot[:, :, None], length[:, :, None], MAX)
    _check(mine, ref)
