"""Batched closest-point kernels for 2D shapes.

Every function works on tensors with arbitrary leading batch dimensions ``...``
that broadcast against each other: points are ``[..., 2]`` and angles, lengths
and widths are ``[...]`` (no trailing singleton dim). Lengths and widths may also
be python floats. Results live on the device and dtype of the first point input.

Shape conventions (shared with collisions and the Lidar):

* a segment (``Line`` entity) is centred at ``center`` with direction
  ``d = (cos rot, sin rot)``; its endpoints are ``plus = center + d * length / 2``
  and ``minus = center - d * length / 2``;
* a box spans ``length`` along its body x axis ``d`` and ``width`` along its body
  y axis ``n = (cos(rot + pi/2), sin(rot + pi/2))``.

Whenever several candidate answers are equally good the first one (in the order
documented per function) wins, since ``torch.argmin`` returns the first minimum.
The arithmetic is ordered so that results track VMAS 1.5 to float precision,
which keeps tie-breaking between near-equal candidates consistent with it.
"""
from __future__ import annotations

import math
from typing import List, Sequence, Tuple, Union

import torch
from torch import Tensor

from vmas_ros.simulator.thresholds import STACKED_SIDES_MAX_ELEMENTS
from vmas_ros.simulator.utils import LINE_MIN_DIST

__all__ = [
    "rotate",
    "dot2",
    "cross2",
    "segment_endpoints",
    "closest_point_on_segment",
    "closest_point_on_segment_xy",
    "segment_intersection",
    "closest_points_segment_segment",
    "box_edges",
    "closest_point_on_box_boundary",
    "closest_point_on_box_boundary_xy",
    "closest_points_box_segment",
    "closest_points_box_box",
    "solid_box_inner_point",
    "point_segment_distance",
    "point_box_distance",
    "disc_box_overlap",
    "disc_box_overlap_xy",
]

Scalar = Union[Tensor, float]


def _as_tensor(x: Scalar, like: Tensor) -> Tensor:
    """Turn a python number (or tensor) into a tensor on ``like``'s device/dtype."""
    return torch.as_tensor(x, dtype=like.dtype, device=like.device)


def broadcast_shape(*shapes: Sequence[int]) -> Tuple[int, ...]:
    """The shape ``shapes`` broadcast to, in plain Python (raises ValueError if they do not).

    ``torch.broadcast_shapes`` imports sympy on first use, whose resident
    memory a simulation never needs.
    """
    n = max([len(shape) for shape in shapes] + [0])  # (a list, not a generator: torch.compile traces this)
    result = [1] * n
    for shape in shapes:
        for i, size in enumerate(shape, start=n - len(shape)):
            if size != 1:
                if result[i] not in (1, size):
                    raise ValueError(f"shapes {[tuple(s) for s in shapes]} do not broadcast")
                result[i] = size
    return tuple(result)


def _broadcast(
    vectors: Sequence[Tensor], scalars: Sequence[Scalar]
) -> Tuple[List[Tensor], List[Tensor]]:
    """Expand ``[..., 2]`` vectors and ``[...]`` scalars to one common batch shape.

    Needed before stacking candidates built from different inputs; expand only
    creates views, so this costs no memory.
    """
    ref = vectors[0]
    scal = [_as_tensor(s, ref) for s in scalars]
    shape = broadcast_shape(*(v.shape[:-1] for v in vectors), *(s.shape for s in scal))
    return [v.expand(*shape, 2) for v in vectors], [s.expand(shape) for s in scal]


def _unit(angle: Tensor) -> Tensor:
    """Unit vector ``[..., 2]`` pointing along ``angle``."""
    return torch.stack([torch.cos(angle), torch.sin(angle)], dim=-1)


def _pick(candidates: Tensor, index: Tensor) -> Tensor:
    """Select ``candidates[..., index, :]`` from ``[..., K, 2]`` with ``index`` ``[...]``."""
    idx = index[..., None, None].expand(*index.shape, 1, candidates.shape[-1])
    return candidates.gather(-2, idx).squeeze(-2)


def _nearest_pair(first: Tensor, second: Tensor) -> Tuple[Tensor, Tensor]:
    """Among K candidate pairs ``[..., K, 2]`` return the closest one (first on ties)."""
    index = torch.linalg.vector_norm(first - second, dim=-1).argmin(dim=-1)
    return _pick(first, index), _pick(second, index)


def norm_xy(x: Tensor, y: Tensor) -> Tensor:
    """Length of the vectors ``(x, y)``, rounded exactly as ``torch.linalg.vector_norm`` rounds it.

    ``sqrt(x * x + y * y)`` differs from it in the last bit for about a fifth
    of all inputs, and contact forces switch on at a distance threshold: code
    that must match VMAS bit for bit measures lengths with this.
    """
    return torch.linalg.vector_norm(torch.stack([x, y], dim=-1), dim=-1)


def hypot_xy(x: Tensor, y: Tensor) -> Tensor:
    """``sqrt(x * x + y * y)``: the fast length, equal to :func:`norm_xy` to float rounding."""
    return torch.addcmul(x * x, y, y).sqrt_()


def rotate(vec: Tensor, angle: Scalar) -> Tensor:
    """Rotate ``[..., 2]`` vectors counter-clockwise by ``angle`` ``[...]`` radians."""
    angle = _as_tensor(angle, vec)
    c, s = torch.cos(angle), torch.sin(angle)
    x, y = vec[..., 0], vec[..., 1]
    return torch.stack([x * c - y * s, x * s + y * c], dim=-1)


def dot2(a: Tensor, b: Tensor) -> Tensor:
    """Dot product of ``[..., 2]`` vectors -> ``[...]``.

    Bit-equal to ``(a * b).sum(-1)`` (a sum of two terms rounds once either way)
    and far faster: torch's reduction over a trailing dim of two
    is far slower than two products and an add.
    """
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def cross2(a: Tensor, b: Tensor) -> Tensor:
    """Scalar 2D cross product ``a.x * b.y - a.y * b.x`` -> ``[...]``."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def segment_endpoints(center: Tensor, rot: Scalar, length: Scalar) -> Tuple[Tensor, Tensor]:
    """Endpoints ``(plus, minus)`` of a segment, ``center +- d * length / 2``."""
    rot, length = _as_tensor(rot, center), _as_tensor(length, center)
    half = _unit(rot) * (length / 2)[..., None]
    return center + half, center - half


def closest_point_on_segment(
    center: Tensor, rot: Scalar, length: Scalar, point: Tensor
) -> Tensor:
    """Projection of ``point`` on the segment's line, clamped to the segment."""
    rot, length = _as_tensor(rot, center), _as_tensor(length, center)
    d = _unit(rot)
    along = dot2(point - center, d)
    half = length / 2
    along = torch.maximum(torch.minimum(along, half), -half)
    return center + along[..., None] * d


def closest_point_on_segment_xy(
    cx: Tensor, cy: Tensor, rot: Tensor, length: Scalar, px: Tensor, py: Tensor
) -> Tuple[Tensor, Tensor]:
    """:func:`closest_point_on_segment` on separate x/y components (same float arithmetic)."""
    dx, dy = torch.cos(rot), torch.sin(rot)
    along = (px - cx) * dx + (py - cy) * dy
    half = length / 2
    along = torch.maximum(torch.minimum(along, half), -half)
    return cx + along * dx, cy + along * dy


def segment_intersection(
    a_plus: Tensor, a_minus: Tensor, b_plus: Tensor, b_minus: Tensor
) -> Tuple[Tensor, Tensor]:
    """Crossing point of segments ``a_plus->a_minus`` and ``b_plus->b_minus``.

    Returns ``(point, hit)``. ``hit`` is True iff the directions are not parallel
    and both segment parameters lie in ``[0, 1]`` (endpoints count). Where
    ``hit`` is False ``point`` is a finite placeholder (``a_plus + t * r`` with a
    guarded denominator) and must be ignored. Parallel or collinear segments
    never hit, even if they overlap. Safe denominators keep gradients NaN-free.
    """
    r = a_minus - a_plus
    s = b_minus - b_plus
    w = b_plus - a_plus
    rxs = cross2(r, s)
    parallel = rxs == 0
    rxs_safe = torch.where(parallel, torch.ones_like(rxs), rxs)
    t = cross2(w, s) / rxs_safe  # parameter along a
    u = cross2(w, r) / rxs_safe  # parameter along b
    hit = ~parallel & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    return a_plus + t[..., None] * r, hit


def closest_points_segment_segment(
    center_a: Tensor,
    rot_a: Scalar,
    len_a: Scalar,
    center_b: Tensor,
    rot_b: Scalar,
    len_b: Scalar,
) -> Tuple[Tensor, Tensor]:
    """Closest pair of points ``(pa, pb)`` between segments a and b.

    Candidates, in tie-breaking order: ``(a_plus, on b)``, ``(a_minus, on b)``,
    ``(on a, b_plus)``, ``(on a, b_minus)``. Intersecting segments return the
    crossing point twice (distance zero).
    """
    (center_a, center_b), (rot_a, len_a, rot_b, len_b) = _broadcast(
        (center_a, center_b), (rot_a, len_a, rot_b, len_b)
    )
    a_plus, a_minus = segment_endpoints(center_a, rot_a, len_a)
    b_plus, b_minus = segment_endpoints(center_b, rot_b, len_b)
    ends_a = torch.stack([a_plus, a_minus], dim=-2)
    ends_b = torch.stack([b_plus, b_minus], dim=-2)
    # Project both endpoints of each segment on the other one in a single call.
    on_b = closest_point_on_segment(center_b[..., None, :], rot_b[..., None], len_b[..., None], ends_a)
    on_a = closest_point_on_segment(center_a[..., None, :], rot_a[..., None], len_a[..., None], ends_b)
    pa, pb = _nearest_pair(torch.cat([ends_a, on_a], dim=-2), torch.cat([on_b, ends_b], dim=-2))

    crossing, hit = segment_intersection(a_plus, a_minus, b_plus, b_minus)
    hit = hit[..., None]
    return torch.where(hit, crossing, pa), torch.where(hit, crossing, pb)


def box_edges(
    center: Tensor, rot: Scalar, length: Scalar, width: Scalar
) -> Tuple[Tensor, Tensor, Tensor]:
    """The 4 box sides as segments: ``(centers [...,4,2], rots [...,4], lengths [...,4])``.

    Order: +x side, -x side (both along ``n``, length ``width``), then +y side,
    -y side (both along ``d``, length ``length``).
    """
    (center,), (rot, length, width) = _broadcast((center,), (rot, length, width))
    d = _unit(rot) * (length / 2)[..., None]
    n = _unit(rot + math.pi / 2) * (width / 2)[..., None]
    centers = torch.stack([center + d, center - d, center + n, center - n], dim=-2)
    across = rot + math.pi / 2
    rots = torch.stack([across, across, rot, rot], dim=-1)
    lengths = torch.stack([width, width, length, length], dim=-1)
    return centers, rots, lengths


def closest_point_on_box_boundary(
    center: Tensor, rot: Scalar, length: Scalar, width: Scalar, point: Tensor
) -> Tensor:
    """Nearest point on the box outline (also for points inside the box)."""
    (center, point), (rot, length, width) = _broadcast((center, point), (rot, length, width))
    x, y = closest_point_on_box_boundary_xy(center[..., 0], center[..., 1], rot, length, width, point[..., 0], point[..., 1])
    return torch.stack([x, y], dim=-1)


def closest_point_on_box_boundary_xy(
    cx: Tensor, cy: Tensor, rot: Tensor, length: Scalar, width: Scalar, px: Tensor, py: Tensor
) -> Tuple[Tensor, Tensor]:
    """:func:`closest_point_on_box_boundary` on separate x/y components.

    Each side's candidate is the same float arithmetic as
    :func:`closest_point_on_segment` on that side, and the first side in
    :func:`box_edges` order wins ties. Two bit-identical layouts, chosen by size
    (this kernel is the box-sphere contact of every substep): small batches stack
    the four sides on a leading dim and pick with one ``argmin`` (fewer ops);
    large ones keep a running minimum over the sides on separate x/y tensors
    (there ``argmin`` and ``gather`` over big stacks cost more than the extra ops).
    """
    n = max(t.numel() for t in (cx, cy, px, py, torch.as_tensor(rot)))
    if n <= STACKED_SIDES_MAX_ELEMENTS:
        return _box_boundary_stacked(cx, cy, rot, length, width, px, py)
    return _box_boundary_running(cx, cy, rot, length, width, px, py)



def closest_point_on_box_boundary_in_frame(
    cx: Tensor, cy: Tensor, rot: Tensor, length: Tensor, width: Tensor, px: Tensor, py: Tensor
) -> Tuple[Tensor, Tensor]:
    """The closest point of a box's boundary to ``(px, py)``, found in the box frame.

    The same point as :func:`closest_point_on_box_boundary_xy`'s side-by-side
    search, in about a third of the passes: express the point in the box
    frame, clamp it to the half extents (an outside point's closest boundary
    point), move an inside point onto the nearer side (the length-axis ends win
    ties, as the first sides do in the search), and rotate back. Agrees with the
    search to float rounding, not bit for bit, so the step uses it only where
    VMAS parity is not promised bit for bit (worlds without joints).
    ``length``/``width`` broadcast against the points (``[P, 1]`` columns).
    """
    cos_r, sin_r = torch.cos(rot), torch.sin(rot)
    rx, ry = px - cx, py - cy
    lx = torch.addcmul(rx * cos_r, ry, sin_r)  # along the length axis
    ly = torch.addcmul(ry * cos_r, rx, sin_r, value=-1)  # along the width axis
    half_l, half_w = length / 2, width / 2
    qx, qy = torch.minimum(torch.maximum(lx, -half_l), half_l), torch.minimum(torch.maximum(ly, -half_w), half_w)
    room_x, room_y = half_l - lx.abs(), half_w - ly.abs()  # both >= 0: inside (clamping changed nothing)
    inside = torch.ge(torch.minimum(room_x, room_y), 0, out=room_x.new_empty(room_x.shape))
    to_end = inside * torch.le(room_x, room_y, out=room_x.new_empty(room_x.shape))  # onto x = +-half_l
    to_side = inside - to_end  # onto y = +-half_w
    qx = torch.addcmul(qx, to_end, torch.copysign(half_l, lx) - qx)
    qy = torch.addcmul(qy, to_side, torch.copysign(half_w, ly) - qy)
    return cx + (qx * cos_r - qy * sin_r), cy + (qx * sin_r + qy * cos_r)



def _box_sides(cx: Tensor, cy: Tensor, rot: Tensor, length: Scalar, width: Scalar) -> tuple:
    """Per side, in box_edges order: (centre x, centre y, direction x, direction y, half length)."""
    across = rot + math.pi / 2
    cos_d, sin_d, cos_n, sin_n = torch.cos(rot), torch.sin(rot), torch.cos(across), torch.sin(across)
    half_l, half_w = length / 2, width / 2
    dx, dy, nx, ny = cos_d * half_l, sin_d * half_l, cos_n * half_w, sin_n * half_w
    return (
        (cx + dx, cy + dy, cos_n, sin_n, half_w),
        (cx - dx, cy - dy, cos_n, sin_n, half_w),
        (cx + nx, cy + ny, cos_d, sin_d, half_l),
        (cx - nx, cy - ny, cos_d, sin_d, half_l),
    )


def _box_boundary_stacked(cx, cy, rot, length, width, px, py) -> Tuple[Tensor, Tensor]:
    (ex0, ey0, ux0, uy0, hw), (ex1, ey1, _, _, _), (ex2, ey2, ux2, uy2, hl), (ex3, ey3, _, _, _) = _box_sides(
        cx, cy, rot, length, width)
    hw, hl = _as_tensor(hw, px), _as_tensor(hl, px)
    # the four sides on a leading dim; everything else broadcasts as it comes
    ex, ey = torch.stack([ex0, ex1, ex2, ex3]), torch.stack([ey0, ey1, ey2, ey3])
    ux, uy = torch.stack([ux0, ux0, ux2, ux2]), torch.stack([uy0, uy0, uy2, uy2])
    half = torch.stack(torch.broadcast_tensors(hw, hw, hl, hl))
    along = (px - ex) * ux + (py - ey) * uy
    along = torch.maximum(torch.minimum(along, half), -half)
    qx, qy = ex + along * ux, ey + along * uy
    # vector_norm over a contiguous [..., 2] rounds the distance (and so breaks near-ties) as VMAS does
    dist = torch.linalg.vector_norm(torch.stack(torch.broadcast_tensors(px - qx, py - qy), dim=-1), dim=-1)
    pick = dist.argmin(dim=0, keepdim=True)  # the first side wins ties
    qx, qy = torch.broadcast_tensors(qx, qy, dist)[:2]
    return qx.gather(0, pick).squeeze(0), qy.gather(0, pick).squeeze(0)


def _box_boundary_running(cx, cy, rot, length, width, px, py) -> Tuple[Tensor, Tensor]:
    best_x = best_y = best_dist = None
    for ex, ey, ux, uy, half in _box_sides(cx, cy, rot, length, width):
        along = (px - ex) * ux + (py - ey) * uy
        along = torch.maximum(torch.minimum(along, half), -half)
        qx, qy = ex + along * ux, ey + along * uy
        # the distance as vector_norm over a contiguous [..., 2] rounds it (and so breaks
        # near-ties between sides) exactly as VMAS does; gx * gx + gy * gy would not
        dist = torch.linalg.vector_norm(torch.stack([px - qx, py - qy], dim=-1), dim=-1)
        if best_dist is None:
            best_x, best_y, best_dist = qx, qy, dist
        else:
            closer = torch.lt(dist, best_dist, out=dist.new_empty(dist.shape))  # float 0/1: where() is slow on CPU
            best_x, best_y = qx * closer + best_x * (1 - closer), qy * closer + best_y * (1 - closer)
            best_dist = torch.minimum(dist, best_dist)
    return best_x, best_y


def closest_points_box_segment(
    box_center: Tensor,
    box_rot: Scalar,
    box_length: Scalar,
    box_width: Scalar,
    seg_center: Tensor,
    seg_rot: Scalar,
    seg_length: Scalar,
) -> Tuple[Tensor, Tensor]:
    """Closest pair ``(p_box, p_seg)`` between a box outline and a segment.

    Each box edge (in :func:`box_edges` order) is paired with the segment via
    :func:`closest_points_segment_segment`; the nearest pair wins.
    """
    (box_center, seg_center), (box_rot, box_length, box_width, seg_rot, seg_length) = _broadcast(
        (box_center, seg_center), (box_rot, box_length, box_width, seg_rot, seg_length)
    )
    centers, rots, lengths = box_edges(box_center, box_rot, box_length, box_width)
    on_box, on_seg = closest_points_segment_segment(
        centers, rots, lengths, seg_center[..., None, :], seg_rot[..., None], seg_length[..., None]
    )
    return _nearest_pair(on_box, on_seg)


def closest_points_box_box(
    c1: Tensor,
    r1: Scalar,
    l1: Scalar,
    w1: Scalar,
    c2: Tensor,
    r2: Scalar,
    l2: Scalar,
    w2: Scalar,
) -> Tuple[Tensor, Tensor]:
    """Closest pair ``(p1, p2)`` between the outlines of box 1 and box 2.

    Candidates, in tie-breaking order: each edge of box 1 against box 2, then
    each edge of box 2 against box 1 (see :func:`closest_points_box_segment`).
    """
    (c1, c2), (r1, l1, w1, r2, l2, w2) = _broadcast((c1, c2), (r1, l1, w1, r2, l2, w2))
    e1_centers, e1_rots, e1_lengths = box_edges(c1, r1, l1, w1)
    e2_centers, e2_rots, e2_lengths = box_edges(c2, r2, l2, w2)

    def expand_box(c: Tensor, r: Tensor, l: Tensor, w: Tensor):
        return c[..., None, :], r[..., None], l[..., None], w[..., None]

    on_box2, on_edge1 = closest_points_box_segment(
        *expand_box(c2, r2, l2, w2), e1_centers, e1_rots, e1_lengths
    )
    on_box1, on_edge2 = closest_points_box_segment(
        *expand_box(c1, r1, l1, w1), e2_centers, e2_rots, e2_lengths
    )
    return _nearest_pair(torch.cat([on_edge1, on_box1], dim=-2), torch.cat([on_box2, on_edge2], dim=-2))


def solid_box_inner_point(
    outside_point: Tensor, surface_point: Tensor, box_center: Tensor
) -> Tuple[Tensor, Tensor]:
    """Point behind the surface so a solid (non-hollow) box pushes objects out.

    Moves ``surface_point`` further along ``v = surface_point - outside_point`` by
    the projection of ``box_center - surface_point`` on ``v``. Returns
    ``(inner_point, depth)`` with ``depth >= 0`` the length of that move. Where
    ``v`` is zero (the outside point lies on the surface) the surface point and a
    zero depth are returned, with finite gradients.
    """
    v = surface_point - outside_point
    u = box_center - surface_point
    v_norm = torch.linalg.vector_norm(v, dim=-1)
    degenerate = v_norm == 0
    v_norm_safe = torch.where(degenerate, torch.ones_like(v_norm), v_norm)
    depth_signed = dot2(v, u) / v_norm_safe
    depth_signed = torch.where(degenerate, torch.zeros_like(depth_signed), depth_signed)
    inner = surface_point + (v / v_norm_safe[..., None]) * depth_signed[..., None]
    return inner, depth_signed.abs()


def point_segment_distance(center: Tensor, rot: Scalar, length: Scalar, point: Tensor) -> Tensor:
    """Euclidean distance ``[...]`` from ``point`` to the segment."""
    return torch.linalg.vector_norm(point - closest_point_on_segment(center, rot, length, point), dim=-1)


def point_box_distance(
    center: Tensor, rot: Scalar, length: Scalar, width: Scalar, point: Tensor
) -> Tensor:
    """Euclidean distance ``[...]`` from ``point`` to the box outline."""
    nearest = closest_point_on_box_boundary(center, rot, length, width, point)
    return torch.linalg.vector_norm(point - nearest, dim=-1)


def disc_box_overlap_xy(
    cx: Tensor, cy: Tensor, rot: Tensor, length: Scalar, width: Scalar, px: Tensor, py: Tensor, radius: float,
    exact: bool = True,
) -> Tuple[Tensor, Tensor]:
    """``(centre distance, overlapping)`` of a disc at ``(px, py)`` and a solid box, on x/y components.

    The disc overlaps the box when its centre is inside the box (closer to
    the box's centre than the outline point nearest it) or when that outline
    point is within ``radius + LINE_MIN_DIST`` of its centre: VMAS 1.5's test.
    ``exact``: the outline point and lengths round as VMAS's do
    (:func:`closest_point_on_box_boundary_xy`, :func:`norm_xy`); otherwise the
    box-frame search and :func:`hypot_xy`, equal to float rounding in far
    fewer passes (``length``/``width`` then tensors). Inputs broadcast.
    """
    closest = closest_point_on_box_boundary_xy if exact else closest_point_on_box_boundary_in_frame
    length_of = norm_xy if exact else hypot_xy
    qx, qy = closest(cx, cy, rot, length, width, px, py)
    distance = length_of(px - cx, py - cy)
    inside = distance < length_of(cx - qx, cy - qy)
    touching = length_of(px - qx, py - qy) < radius + LINE_MIN_DIST
    return distance, inside | touching


def disc_box_overlap(center: Tensor, rot: Scalar, length: Scalar, width: Scalar, disc: Tensor, radius: float) -> Tensor:
    """Does the disc at ``disc`` ``[..., 2]`` overlap the solid box? Bool ``[...]``, VMAS's rounding.

    :func:`disc_box_overlap_xy` on ``[..., 2]`` points; inputs broadcast.
    """
    (center, disc), (rot, length, width) = _broadcast((center, disc), (rot, length, width))
    _, overlapping = disc_box_overlap_xy(
        center[..., 0], center[..., 1], rot, length, width, disc[..., 0], disc[..., 1], radius
    )
    return overlapping
