"""Box-line contacts: the closest points of the box's boundary and the segment."""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.physics.collision.contact import PairForces, Pushes, centres, cross, rows, solid_inner, with_torques
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import PairTable
from vmas_ros.simulator.utils import LINE_MIN_DIST


def forces(pair: PairTable, q: Tensor, params: StepParams, exact: bool) -> PairForces:
    """Forces and torques ``[3, P, B]`` on the boxes (a) and lines (b), from ``q`` ``[3, N, B]``
    (always VMAS's rounding: the candidate search picks among near-equal distances)."""
    p, ia, ib = pair.params, pair.index_a, pair.index_b
    xa, ya, xb, yb = centres(pair, q)
    push = Pushes(xa - xb, ya - yb, p["reach"], params)
    on_box, on_line = geo.closest_points_box_segment(
        torch.stack([xa, ya], dim=-1), rows(q[2], ia), p["a_length"], p["a_width"],
        torch.stack([xb, yb], dim=-1), rows(q[2], ib), p["b_length"],
    )
    (bx, by), (lx, ly) = on_box.unbind(-1), on_line.unbind(-1)
    ax, ay, depth = solid_inner(lx, ly, bx, by, xa, ya, p["a_solid"])
    fx, fy = push(ax, ay, lx, ly, LINE_MIN_DIST + depth)
    return with_torques(fx, fy, cross(bx - xa, by - ya, fx, fy), -fx, -fy, cross(lx - xb, ly - yb, -fx, -fy))
