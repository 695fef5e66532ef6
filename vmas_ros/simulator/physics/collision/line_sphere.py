"""Line-sphere contacts: the sphere's centre against its closest point on the segment."""
from __future__ import annotations

from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.physics.collision.contact import PairForces, Pushes, centres, cross, rows, with_torques
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import PairTable
from vmas_ros.simulator.utils import LINE_MIN_DIST


def forces(pair: PairTable, q: Tensor, params: StepParams, exact: bool) -> PairForces:
    """Forces and torques ``[3, P, B]`` on the lines (a) and spheres (b), from ``q`` ``[3, N, B]``."""
    p, ia, ib = pair.params, pair.index_a, pair.index_b
    xa, ya, xb, yb = centres(pair, q)
    push = Pushes(xa - xb, ya - yb, p["reach"], params)
    qx, qy = geo.closest_point_on_segment_xy(xa, ya, rows(q[2], ia), p["a_length"], xb, yb)
    fbx, fby = push(xb, yb, qx, qy, p["b_radius"] + LINE_MIN_DIST)
    return with_torques(-fbx, -fby, cross(qx - xa, qy - ya, -fbx, -fby), fbx, fby, None)
