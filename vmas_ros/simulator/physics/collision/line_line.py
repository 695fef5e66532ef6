"""Line-line contacts: the closest points of the two segments."""
from __future__ import annotations

import torch
from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.physics.collision.contact import PairForces, Pushes, centres, cross, rows, with_torques
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import PairTable
from vmas_ros.simulator.utils import LINE_MIN_DIST


def forces(pair: PairTable, q: Tensor, params: StepParams, exact: bool) -> PairForces:
    """Forces and torques ``[3, P, B]`` on both lines, from ``q`` ``[3, N, B]`` (always VMAS's rounding:
    the candidate search picks among near-equal distances)."""
    p, ia, ib = pair.params, pair.index_a, pair.index_b
    xa, ya, xb, yb = centres(pair, q)
    push = Pushes(xa - xb, ya - yb, p["reach"], params)
    ca, cb = geo.closest_points_segment_segment(
        torch.stack([xa, ya], dim=-1), rows(q[2], ia), p["a_length"],
        torch.stack([xb, yb], dim=-1), rows(q[2], ib), p["b_length"],
    )
    (cax, cay), (cbx, cby) = ca.unbind(-1), cb.unbind(-1)
    fx, fy = push(cax, cay, cbx, cby, torch.full_like(p["a_length"], LINE_MIN_DIST))
    return with_torques(fx, fy, cross(cax - xa, cay - ya, fx, fy), -fx, -fy, cross(cbx - xb, cby - yb, -fx, -fy))
