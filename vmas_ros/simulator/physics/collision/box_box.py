"""Box-box contacts: the closest points of the two boundaries, each pushed from inside a solid box."""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.physics.collision.contact import PairForces, Pushes, centres, cross, rows, solid_inner, with_torques
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import PairTable
from vmas_ros.simulator.utils import LINE_MIN_DIST


def forces(pair: PairTable, q: Tensor, params: StepParams, exact: bool) -> PairForces:
    """Forces and torques ``[3, P, B]`` on both boxes, from ``q`` ``[3, N, B]`` (always VMAS's rounding:
    the candidate search picks among near-equal distances)."""
    p, ia, ib = pair.params, pair.index_a, pair.index_b
    xa, ya, xb, yb = centres(pair, q)
    push = Pushes(xa - xb, ya - yb, p["reach"], params)
    on_a, on_b = geo.closest_points_box_box(
        torch.stack([xa, ya], dim=-1), rows(q[2], ia), p["a_length"], p["a_width"],
        torch.stack([xb, yb], dim=-1), rows(q[2], ib), p["b_length"], p["b_width"],
    )
    (oax, oay), (obx, oby) = on_a.unbind(-1), on_b.unbind(-1)
    aax, aay, depth_a = solid_inner(obx, oby, oax, oay, xa, ya, p["a_solid"])
    abx, aby, depth_b = solid_inner(oax, oay, obx, oby, xb, yb, p["b_solid"])
    fx, fy = push(aax, aay, abx, aby, depth_a + depth_b + LINE_MIN_DIST)
    return with_torques(fx, fy, cross(oax - xa, oay - ya, fx, fy), -fx, -fy, cross(obx - xb, oby - yb, -fx, -fy))
