"""Box-sphere contacts: the sphere's centre against its closest point on the box's boundary.

A solid box pushes from its inside (see ``contact.solid_inner``), so a sphere
that got in is pushed out.
"""
from __future__ import annotations

from torch import Tensor

from vmas_ros.simulator import geometry as geo
from vmas_ros.simulator.physics.collision.contact import PairForces, Pushes, centres, cross, rows, solid_inner, with_torques
from vmas_ros.simulator.physics.types import StepParams
from vmas_ros.simulator.tables import PairTable
from vmas_ros.simulator.utils import LINE_MIN_DIST


def forces(pair: PairTable, q: Tensor, params: StepParams, exact: bool) -> PairForces:
    """Forces and torques ``[3, P, B]`` on the boxes (a) and spheres (b), from ``q`` ``[3, N, B]``.

    ``exact``: VMAS's arithmetic and rounding (worlds with joints, where a
    last-bit difference grows). Otherwise the closest point is found in the
    box's frame with lengths ``sqrt(x * x + y * y)``: the same forces to float
    rounding, in far fewer passes.
    """
    p, ia, ib = pair.params, pair.index_a, pair.index_b
    xa, ya, xb, yb = centres(pair, q)
    push = Pushes(xa - xb, ya - yb, p["reach"], params, length=geo.norm_xy if exact else geo.hypot_xy)
    closest = geo.closest_point_on_box_boundary_xy if exact else geo.closest_point_on_box_boundary_in_frame
    sx, sy = closest(xa, ya, rows(q[2], ia), p["a_length"], p["a_width"], xb, yb)
    ax, ay, depth = solid_inner(xb, yb, sx, sy, xa, ya, p["a_solid"])
    fbx, fby = push(xb, yb, ax, ay, p["b_radius"] + LINE_MIN_DIST + depth)
    return with_torques(-fbx, -fby, cross(sx - xa, sy - ya, -fbx, -fby), fbx, fby, None)
