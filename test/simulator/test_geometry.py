"""Tests for vmas_ros.simulator.geometry: hand-computed cases + VMAS oracle."""
import math

import pytest
import torch

from vmas.simulator.physics import (
    _get_closest_box_box,
    _get_closest_line_box,
    _get_closest_point_box,
    _get_closest_point_line,
    _get_closest_points_line_line,
    _get_inner_point_box,
    _get_intersection_point_line_line,
)

from vmas_ros.simulator import geometry as g

devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
ATOL = 1e-5
N = 4096  # random samples per oracle comparison


@pytest.fixture(params=devices)
def device(request):
    return torch.device(request.param)


def T(x, device, dtype=torch.float32):
    return torch.tensor(x, dtype=dtype, device=device)


def close(a, b, atol=ATOL):
    torch.testing.assert_close(a, b, atol=atol, rtol=0)


def rand(shape, lo, hi, device, gen):
    return torch.rand(shape, generator=gen, device="cpu").to(device) * (hi - lo) + lo


@pytest.fixture
def gen():
    return torch.Generator().manual_seed(0)


# ----------------------------------------------------------------- analytic


def test_rotate_and_cross(device):
    close(g.rotate(T([1.0, 0.0], device), T(math.pi / 2, device)), T([0.0, 1.0], device))
    close(g.rotate(T([1.0, 2.0], device), math.pi), T([-1.0, -2.0], device))
    # [3, 1, 2] vectors broadcast against [4] angles -> [3, 4, 2]
    vec = T([[[1.0, 0.0]], [[0.0, 1.0]], [[1.0, 1.0]]], device)
    angles = T([0.0, 0.5, 1.0, 2.0], device)
    out = g.rotate(vec, angles)
    assert out.shape == (3, 4, 2)
    close(out[2, 3], T([math.cos(2.0) - math.sin(2.0), math.sin(2.0) + math.cos(2.0)], device))
    close(torch.linalg.vector_norm(out, dim=-1), torch.linalg.vector_norm(vec, dim=-1).expand(3, 4))
    assert g.cross2(T([1.0, 0.0], device), T([0.0, 1.0], device)).item() == 1.0
    assert g.cross2(T([2.0, 3.0], device), T([4.0, 5.0], device)).item() == -2.0


def test_segment_endpoints_and_projection(device):
    plus, minus = g.segment_endpoints(T([1.0, 2.0], device), T(math.pi / 2, device), 2.0)
    close(plus, T([1.0, 3.0], device))
    close(minus, T([1.0, 1.0], device))
    c, r = T([0.0, 0.0], device), T(0.0, device)
    pts = T([[0.5, 3.0], [5.0, 1.0], [-5.0, -1.0], [0.0, 0.0]], device)
    exp = T([[0.5, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]], device)
    close(g.closest_point_on_segment(c, r, 2.0, pts), exp)
    close(g.point_segment_distance(c, r, 2.0, pts), T([3.0, math.hypot(4, 1), math.hypot(4, 1), 0.0], device))


def test_segment_intersection(device):
    a_p, a_m = T([-1.0, 0.0], device), T([1.0, 0.0], device)
    b_p = T([[0.0, -1.0], [1.0, 0.0], [-1.0, 1.0], [2.0, -1.0]], device)
    b_m = T([[0.0, 1.0], [1.0, 1.0], [1.0, 1.0], [2.0, 1.0]], device)
    point, hit = g.segment_intersection(a_p, a_m, b_p, b_m)
    # crossing, touching a's end (t = 1), parallel, beyond a's end
    assert hit.tolist() == [True, True, False, False]
    close(point[:2], T([[0.0, 0.0], [1.0, 0.0]], device))
    assert torch.isfinite(point).all()


def test_segment_segment_cases(device):
    zero = T(0.0, device)
    # parallel overlap: candidates 0 and 3 tie at distance 1, the first one wins
    pa, pb = g.closest_points_segment_segment(T([0.0, 0.0], device), zero, 2.0, T([1.5, 1.0], device), zero, 2.0)
    close(pa, T([1.0, 0.0], device))
    close(pb, T([1.0, 1.0], device))
    # crossing segments -> both points at the crossing
    pa, pb = g.closest_points_segment_segment(
        T([0.0, 0.0], device), zero, 2.0, T([0.5, 0.0], device), T(math.pi / 2, device), 2.0
    )
    close(pa, T([0.5, 0.0], device))
    close(pb, T([0.5, 0.0], device))
    # T configuration, end of a against the middle of b
    pa, pb = g.closest_points_segment_segment(
        T([0.0, 0.0], device), zero, 2.0, T([3.0, 0.0], device), T(math.pi / 2, device), 2.0
    )
    close(pa, T([1.0, 0.0], device))
    close(pb, T([3.0, 0.0], device))
    # end of b against the middle of a
    pa, pb = g.closest_points_segment_segment(
        T([0.0, 0.0], device), zero, 4.0, T([0.5, 2.0], device), T(math.pi / 2, device), 2.0
    )
    close(pa, T([0.5, 0.0], device))
    close(pb, T([0.5, 1.0], device))


def test_box_edges(device):
    centers, rots, lengths = g.box_edges(T([0.0, 0.0], device), T(0.0, device), 4.0, 2.0)
    close(centers, T([[2.0, 0.0], [-2.0, 0.0], [0.0, 1.0], [0.0, -1.0]], device))
    close(rots, T([math.pi / 2, math.pi / 2, 0.0, 0.0], device))
    close(lengths, T([2.0, 2.0, 4.0, 4.0], device))


def test_closest_point_on_box_boundary(device):
    c = T([0.0, 0.0], device)
    pts = T([[5.0, 0.5], [1.5, 0.2], [3.0, 3.0], [0.0, 0.0], [-1.0, -4.0]], device)
    out = g.closest_point_on_box_boundary(c, T(0.0, device), 4.0, 2.0, pts)
    # outside, inside (nearest outline), corner, centre (tie edge 2 vs 3 -> edge 2), below
    close(out, T([[2.0, 0.5], [2.0, 0.2], [2.0, 1.0], [0.0, 1.0], [-1.0, -1.0]], device))
    close(g.point_box_distance(c, T(0.0, device), 4.0, 2.0, pts), T([3.0, 0.5, math.hypot(1, 2), 1.0, 3.0], device))
    # rotated by 90 degrees: length now spans y
    out = g.closest_point_on_box_boundary(c, T(math.pi / 2, device), 4.0, 2.0, T([0.5, 5.0], device))
    close(out, T([0.5, 2.0], device))


def test_box_segment_cases(device):
    c, zero = T([0.0, 0.0], device), T(0.0, device)
    pb, ps = g.closest_points_box_segment(c, zero, 2.0, 2.0, T([3.0, 0.0], device), zero, 2.0)
    close(pb, T([1.0, 0.0], device))
    close(ps, T([2.0, 0.0], device))
    # segment crossing the +x side
    pb, ps = g.closest_points_box_segment(c, zero, 2.0, 2.0, T([1.0, 0.0], device), zero, 1.0)
    close(pb, T([1.0, 0.0], device))
    close(ps, T([1.0, 0.0], device))
    # segment fully inside: nearest outline point to its +x end
    pb, ps = g.closest_points_box_segment(c, zero, 4.0, 4.0, T([0.5, 0.0], device), zero, 2.0)
    close(pb, T([2.0, 0.0], device))
    close(ps, T([1.5, 0.0], device))


def test_box_box_cases(device):
    c, zero = T([0.0, 0.0], device), T(0.0, device)
    # diagonal gap: corner to corner
    p1, p2 = g.closest_points_box_box(c, zero, 2.0, 2.0, T([3.0, 3.0], device), zero, 2.0, 2.0)
    close(p1, T([1.0, 1.0], device))
    close(p2, T([2.0, 2.0], device))
    # overlapping corners: first candidate is box-1 edge 0 crossing box-2 edge 3
    p1, p2 = g.closest_points_box_box(c, zero, 2.0, 2.0, T([1.5, 1.5], device), zero, 2.0, 2.0)
    close(p1, T([1.0, 0.5], device))
    close(p2, T([1.0, 0.5], device))
    # parallel faces, gap 1: any horizontal pair across the overlap is optimal
    p1, p2 = g.closest_points_box_box(c, zero, 2.0, 2.0, T([3.0, 0.5], device), zero, 2.0, 2.0)
    close(torch.linalg.vector_norm(p1 - p2), T(1.0, device))
    close(p1[0], T(1.0, device))
    close(p2[0], T(2.0, device))
    assert -0.5 - ATOL <= p1[1].item() <= 1.0 + ATOL
    # rotated box 2 (diamond) pointing its vertex at box 1's +x face
    p1, p2 = g.closest_points_box_box(
        c, zero, 2.0, 2.0, T([2.0 + math.sqrt(2), 0.0], device), T(math.pi / 4, device), 2.0, 2.0
    )
    close(p1, T([1.0, 0.0], device))
    close(p2, T([2.0, 0.0], device))


def test_solid_box_inner_point(device):
    outside = T([[3.0, 0.0], [1.5, 0.5], [1.0, 0.5]], device, torch.float64).requires_grad_()
    surface = T([[1.0, 0.0], [1.0, 0.5], [1.0, 0.5]], device, torch.float64)
    inner, depth = g.solid_box_inner_point(outside, surface, T([0.0, 0.0], device, torch.float64))
    close(inner.detach(), T([[0.0, 0.0], [0.0, 0.5], [1.0, 0.5]], device, torch.float64))
    close(depth.detach(), T([1.0, 1.0, 0.0], device, torch.float64))
    (inner.sum() + depth.sum()).backward()
    assert torch.isfinite(outside.grad).all()


def test_broadcast_dtype_and_scalars(device, gen):
    dt = torch.float64
    B, P = 3, 5
    c1 = rand((B, 1, 2), -1, 1, device, gen).to(dt)
    c2 = rand((1, P, 2), -1, 1, device, gen).to(dt)
    r1, r2 = rand((B, 1), -3, 3, device, gen).to(dt), rand((P,), -3, 3, device, gen).to(dt)
    p1, p2 = g.closest_points_box_box(c1, r1, 1.0, 0.5, c2, r2, 0.7, 0.3)
    assert p1.shape == (B, P, 2) and p1.dtype == dt and p1.device.type == device.type
    f1, f2 = g.closest_points_box_box(
        c1.expand(B, P, 2).reshape(-1, 2), r1.expand(B, P).reshape(-1), T([1.0] * B * P, device, dt), 0.5,
        c2.expand(B, P, 2).reshape(-1, 2), r2.expand(B, P).reshape(-1), 0.7, T([0.3] * B * P, device, dt),
    )
    close(p1.reshape(-1, 2), f1)
    close(p2.reshape(-1, 2), f2)
    pa, pb = g.closest_points_segment_segment(c1, r1, 1.0, c2, r2, 0.5)
    assert pa.shape == pb.shape == (B, P, 2) and pa.dtype == dt
    pb_, ps_ = g.closest_points_box_segment(c1, r1, 1.0, 1.0, c2, r2, 0.5)
    assert pb_.shape == (B, P, 2)
    assert g.closest_point_on_box_boundary(c1, r1, 1.0, 1.0, c2).shape == (B, P, 2)


def test_gradients_finite_on_degenerate_inputs(device):
    ca = T([0.0, 0.0], device, torch.float64).requires_grad_()
    # parallel, collinear-overlapping and crossing segments
    cb = T([[0.0, 1.0], [0.5, 0.0], [0.3, 0.0]], device, torch.float64)
    rb = T([0.0, 0.0, math.pi / 2], device, torch.float64)
    pa, pb = g.closest_points_segment_segment(ca, T(0.0, device, torch.float64), 2.0, cb, rb, 2.0)
    (pa.sum() + pb.sum()).backward()
    assert torch.isfinite(ca.grad).all()
    assert torch.isfinite(pa).all() and torch.isfinite(pb).all()


# ------------------------------------------------------------ VMAS oracle


def _random_segments(n, device, gen, spread=2.0):
    c = rand((n, 2), -spread, spread, device, gen)
    r = rand((n,), -math.pi, math.pi, device, gen)
    l = rand((n,), 0.1, 3.0, device, gen)
    return c, r, l


def test_oracle_point_on_segment_and_box(device, gen):
    c, r, l = _random_segments(N, device, gen)
    w = rand((N,), 0.1, 3.0, device, gen)
    p = rand((N, 2), -3, 3, device, gen)
    close(g.closest_point_on_segment(c, r, l, p), _get_closest_point_line(c, r[:, None], l, p))
    close(g.closest_point_on_box_boundary(c, r, l, w, p), _get_closest_point_box(c, r[:, None], w, l, p))


def test_oracle_intersection(device, gen):
    pts = [rand((N, 2), -1, 1, device, gen) for _ in range(4)]
    point, hit = g.segment_intersection(*pts)
    ref_point, ref_dist = _get_intersection_point_line_line(*pts)
    ref_hit = (ref_dist == 0).squeeze(-1)
    assert torch.equal(hit, ref_hit)
    assert 0.1 < hit.float().mean().item() < 0.9  # both outcomes exercised
    close(point[hit], ref_point[ref_hit])


def test_oracle_segment_segment(device, gen):
    ca, ra, la = _random_segments(N, device, gen)
    cb, rb, lb = _random_segments(N, device, gen)
    pa, pb = g.closest_points_segment_segment(ca, ra, la, cb, rb, lb)
    ra_, rb_ = _get_closest_points_line_line(ca, ra[:, None], la, cb, rb[:, None], lb)
    close(pa, ra_)
    close(pb, rb_)


def test_oracle_box_segment(device, gen):
    cb, rb, lb = _random_segments(N, device, gen)
    wb = rand((N,), 0.1, 3.0, device, gen)
    cs, rs, ls = _random_segments(N, device, gen)
    p_box, p_seg = g.closest_points_box_segment(cb, rb, lb, wb, cs, rs, ls)
    ref_box, ref_seg = _get_closest_line_box(cb, rb[:, None], wb, lb, cs, rs[:, None], ls)
    close(p_box, ref_box)
    close(p_seg, ref_seg)


def test_oracle_box_box(device, gen):
    c1, r1, l1 = _random_segments(N, device, gen)
    c2, r2, l2 = _random_segments(N, device, gen)
    w1, w2 = rand((N,), 0.1, 3.0, device, gen), rand((N,), 0.1, 3.0, device, gen)
    p1, p2 = g.closest_points_box_box(c1, r1, l1, w1, c2, r2, l2, w2)
    ref1, ref2 = _get_closest_box_box(c1, r1[:, None], w1, l1, c2, r2[:, None], w2, l2)
    close(p1, ref1)
    close(p2, ref2)


def test_oracle_box_box_axis_aligned_ties(device, gen):
    """Touching/parallel boxes produce many tied candidates; the winner must match."""
    c1 = torch.round(rand((N, 2), -2, 2, device, gen) * 4) / 4
    c2 = torch.round(rand((N, 2), -2, 2, device, gen) * 4) / 4
    quarter = torch.randint(0, 4, (N, 2), generator=gen).to(device) * (math.pi / 2)
    size = torch.randint(1, 5, (N, 4), generator=gen).to(device).float() / 2
    p1, p2 = g.closest_points_box_box(c1, quarter[:, 0], size[:, 0], size[:, 1], c2, quarter[:, 1], size[:, 2], size[:, 3])
    ref1, ref2 = _get_closest_box_box(
        c1, quarter[:, :1], size[:, 1], size[:, 0], c2, quarter[:, 1:], size[:, 3], size[:, 2]
    )
    close(p1, ref1)
    close(p2, ref2)


def test_oracle_inner_point(device, gen):
    outside = rand((N, 2), -3, 3, device, gen)
    surface = rand((N, 2), -1, 1, device, gen)
    center = rand((N, 2), -1, 1, device, gen)
    inner, depth = g.solid_box_inner_point(outside, surface, center)
    ref_inner, ref_depth = _get_inner_point_box(outside, surface, center)
    close(inner, ref_inner)
    close(depth, ref_depth)


def test_box_frame_closest_point_agrees_with_the_side_search(device):
    """The box-frame kernel of the contact step finds the search's point (inside, outside, corners)."""
    gen = torch.Generator().manual_seed(3)
    n = 20000
    cx, cy = (torch.rand(2, 1, n, generator=gen) - 0.5).to(device)
    rot = ((torch.rand(1, n, generator=gen) - 0.5) * 7).to(device)
    px, py = cx + (torch.rand(1, n, generator=gen) * 0.8 - 0.4).to(device), cy + (torch.rand(1, n, generator=gen) * 0.8 - 0.4).to(device)
    length, width = torch.tensor([[0.3]], device=device), torch.tensor([[0.15]], device=device)
    sx, sy = g.closest_point_on_box_boundary_xy(cx, cy, rot, length, width, px, py)
    fx, fy = g.closest_point_on_box_boundary_in_frame(cx, cy, rot, length, width, px, py)
    gap = torch.maximum((sx - fx).abs(), (sy - fy).abs())
    # equal to rounding, except where the search meets a float tie between two sides: then both points
    # are (to float precision) equally far: an offset e along the side changes the distance d by
    # e^2 / 2d, which float32 misses while e < sqrt(2 d ulp(d)), about 2e-4 sqrt(d)
    dist = torch.hypot(px - sx, py - sy)
    assert (gap <= 1e-6).float().mean() > 0.999
    assert (gap <= 2e-4 * dist.sqrt() + 1e-6).all()
    torch.testing.assert_close(torch.hypot(px - fx, py - fy), dist, atol=2e-6, rtol=0)
    inside = ((px - cx) * torch.cos(rot) + (py - cy) * torch.sin(rot)).abs() < 0.15
    assert inside.any() and (~inside).any()
