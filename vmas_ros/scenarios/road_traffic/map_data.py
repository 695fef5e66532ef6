"""The CPM Lab road map of ``road_traffic``: lanelets read from VMAS's XML, routes built on them.

The map (a CommonRoad-style XML of 104 lanelets, each a left and a right
boundary polyline) belongs to VMAS and is not shipped here: :func:`locate_map`
finds it inside the installed ``vmas`` package (``pip install vmas==1.5.2``)
without importing ``vmas``, or takes a path the user passes as the
``map_file_path`` kwarg. It is parsed with the standard library.

On that map, :func:`build_routes` lays out the routes agents can be given.
Map type "1" uses 40 routes, each one of seven closed loops of lanelets
entered at some lanelet. A route's centre line is the mean of its lanelets'
own left and right boundaries; the boundaries an agent must not cross are the
outer boundaries of the group of side-by-side lanelets it drives in
("shared" boundaries), so lane changes within a group are not collisions.

:class:`Routes` packs every route into padded tensors so that a reset can
gather the routes of many agents at once by route index.
"""
from __future__ import annotations

import importlib.machinery
import math
import os
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import torch
from torch import Tensor

MAP_FILE = os.path.join("scenarios_data", "road_traffic", "road_traffic_cpm_lab.xml")

#: the seven closed loops of lanelet ids (each listed in driving order)
LOOPS: Tuple[Tuple[int, ...], ...] = (
    (4, 6, 8, 60, 58, 56, 54, 80, 82, 84, 86, 34, 32, 30, 28, 2),
    (1, 3, 23, 10, 12, 17, 43, 38, 36, 49, 29, 27),
    (64, 62, 75, 55, 53, 79, 81, 101, 88, 90, 95, 69),
    (40, 45, 97, 92, 94, 100, 83, 85, 33, 31, 48, 42),
    (5, 7, 59, 57, 74, 68, 66, 71, 19, 14, 16, 22),
    (41, 39, 20, 63, 61, 57, 55, 67, 65, 98, 37, 35, 31, 29),
    (3, 5, 9, 11, 72, 91, 93, 81, 83, 87, 89, 46, 13, 15),
)
#: route i of map type "1": (loop number, first lanelet); loops numbered from 1
LOOP_ROUTES: Tuple[Tuple[int, int], ...] = (
    (1, 4), (2, 1), (3, 64), (4, 42), (5, 22), (6, 39), (7, 15), (1, 8), (2, 10), (3, 75),
    (4, 45), (5, 59), (6, 61), (7, 5), (1, 58), (2, 17), (3, 79), (4, 92), (5, 68), (6, 55),
    (7, 11), (1, 54), (2, 38), (3, 88), (4, 100), (5, 19), (6, 65), (7, 93), (1, 82), (2, 49),
    (3, 95), (4, 33), (5, 14), (6, 35), (7, 83), (1, 86), (6, 29), (7, 89), (1, 32), (1, 28),
)
#: lanelets driven side by side (or overlapping, in the intersection): first member's left
#: boundary and last member's right boundary bound the whole group
SIDE_BY_SIDE: Tuple[Tuple[int, ...], ...] = (
    (4, 3, 22), (6, 5, 23), (8, 7), (60, 59), (58, 57, 75), (56, 55, 74), (54, 53), (80, 79),
    (82, 81, 100), (84, 83, 101), (86, 85), (34, 33), (32, 31, 49), (30, 29, 48), (28, 27), (2, 1),
    (13, 14), (15, 16), (9, 10), (11, 12), (63, 64), (61, 62), (67, 68), (65, 66),
    (91, 92), (93, 94), (87, 88), (89, 90), (37, 38), (35, 36), (41, 42), (39, 40),
    (25, 18), (26, 17), (52, 43), (72, 73), (51, 44), (50, 45), (102, 97), (20, 21),
    (103, 96), (104, 95), (78, 69), (46, 47), (77, 70), (76, 71), (24, 19), (98, 99),
)
#: two boundary points closer than this are the same point where lanelets join
JOIN_TOLERANCE = 1e-4


def locate_map(map_file_path: Optional[str] = None) -> str:
    """Path of the map XML: ``map_file_path`` if given, else the copy inside the installed ``vmas``."""
    if map_file_path is not None:
        if not os.path.isfile(map_file_path):
            raise ValueError(f"road_traffic: map_file_path {map_file_path!r} is not a file")
        return map_file_path
    # the real VMAS on sys.path, found without importing it; PathFinder looks past
    # install_as_vmas(), under which the name vmas resolves to vmas_ros
    spec = importlib.machinery.PathFinder.find_spec("vmas")
    roots = list(spec.submodule_search_locations or []) if spec is not None else []
    for root in roots:
        candidate = os.path.join(root, MAP_FILE)
        if os.path.isfile(candidate):
            return candidate
    raise FileNotFoundError(
        "road_traffic needs VMAS's CPM Lab map (road_traffic_cpm_lab.xml), which is not shipped with "
        "vmas_ros: install VMAS (`pip install vmas==1.5.2`) or pass the file's path as the "
        "`map_file_path` kwarg"
    )


def _polyline(bound: ElementTree.Element) -> List[Tuple[float, float]]:
    return [(float(p.find("x").text), float(p.find("y").text)) for p in bound.findall("point")]


@dataclass
class Lanelet:
    left: Tensor  # [points, 2] left boundary (in driving direction)
    right: Tensor  # [points, 2] right boundary


def parse_map(path: str) -> Dict[int, Lanelet]:
    """Every lanelet of the XML by id: its left and right boundary polylines (float32, CPU)."""
    lanelets = {}
    for element in ElementTree.parse(path).getroot().iter("lanelet"):
        left, right = element.find("leftBound"), element.find("rightBound")
        lanelets[int(element.get("id"))] = Lanelet(
            torch.tensor(_polyline(left), dtype=torch.float32), torch.tensor(_polyline(right), dtype=torch.float32)
        )
    if not lanelets:
        raise ValueError(f"road_traffic: no lanelets in map file {path!r}")
    return lanelets


def mean_lane_width(lanelets: Dict[int, Lanelet]) -> Tensor:
    """Mean distance between paired left and right boundary points over the whole map (scalar)."""
    left = torch.cat([lanelets[k].left for k in sorted(lanelets)])
    right = torch.cat([lanelets[k].right for k in sorted(lanelets)])
    return torch.linalg.vector_norm(left - right, dim=-1).mean()


def _append(chain: Optional[Tensor], piece: Tensor, joined: bool) -> Tensor:
    """``chain`` followed by ``piece``, dropping the piece's first point where the two join."""
    if chain is None:
        return piece
    return torch.cat([chain, piece[1:] if joined else piece])


@dataclass
class Route:
    centre: Tensor  # [points, 2]
    yaw: Tensor  # [points - 1] heading of each centre-line segment
    left: Tensor  # [left points, 2] shared left boundary
    right: Tensor  # [right points, 2] shared right boundary
    is_loop: bool


def build_route(lanelet_ids: Sequence[int], lanelets: Dict[int, Lanelet]) -> Route:
    """Chain the lanelets ``lanelet_ids`` into one route (see the module docstring)."""
    group_of = {member: group for group in SIDE_BY_SIDE for member in group}
    own_left = own_right = shared_left = shared_right = None
    for lanelet_id in lanelet_ids:
        lanelet, group = lanelets[lanelet_id], group_of[lanelet_id]
        outer_left, outer_right = lanelets[group[0]].left, lanelets[group[-1]].right
        # joints are judged on the lanelet's own boundaries and applied to the shared ones too
        left_joined = own_left is not None and float(torch.linalg.vector_norm(own_left[-1] - lanelet.left[0])) < JOIN_TOLERANCE
        right_joined = own_right is not None and float(torch.linalg.vector_norm(own_right[-1] - lanelet.right[0])) < JOIN_TOLERANCE
        own_left, shared_left = _append(own_left, lanelet.left, left_joined), _append(shared_left, outer_left, left_joined)
        own_right, shared_right = _append(own_right, lanelet.right, right_joined), _append(shared_right, outer_right, right_joined)
    centre = (own_left + own_right) / 2
    step = centre.diff(dim=0)
    is_loop = float(torch.linalg.vector_norm(centre[0] - centre[-1])) <= JOIN_TOLERANCE
    return Route(centre, torch.atan2(step[:, 1], step[:, 0]), shared_left, shared_right, is_loop)


def loop_route(loop_number: int, first_lanelet: int) -> List[int]:
    """The lanelets of loop ``loop_number`` (from 1) in driving order, starting at ``first_lanelet``."""
    loop = LOOPS[loop_number - 1]
    start = loop.index(first_lanelet)
    return list(loop[start:] + loop[:start])


@dataclass
class Routes:
    """Every route padded to a common length ``P`` (all on the world's device).

    The centre line is followed by ``n_extension`` points continuing its last
    segment, then by the last of those repeated; boundaries are padded with
    their last point. Padding never changes a distance or a crossing test.
    """

    centre: Tensor  # [R, P, 2]
    yaw: Tensor  # [R, P] segment headings (padded with the last one)
    left: Tensor  # [R, P, 2]
    right: Tensor  # [R, P, 2]
    n_centre: Tensor  # [R] long, real centre-line points
    n_left: Tensor  # [R] long
    n_right: Tensor  # [R] long
    is_loop: Tensor  # [R] bool
    entry: Tensor  # [R, 2, 2] first left and first right boundary point
    exit: Tensor  # [R, 2, 2] last left and last right boundary point


def _pad(points: Tensor, length: int) -> Tensor:
    return torch.cat([points, points[-1:].expand(length - len(points), *points.shape[1:])])


def pack_routes(routes: Sequence[Route], n_extension: int, device) -> Routes:
    """Pad ``routes`` to one tensor each, extending every centre line by ``n_extension`` points."""
    length = max(len(r.centre) for r in routes) + n_extension + 2
    centres = []
    for r in routes:
        steps = torch.arange(1, n_extension + 1, dtype=torch.float32).unsqueeze(1)
        extension = r.centre[-1] + steps * (r.centre[-1] - r.centre[-2])
        centres.append(_pad(torch.cat([r.centre, extension]), length))
    packed = Routes(
        centre=torch.stack(centres),
        yaw=torch.stack([_pad(r.yaw, length) for r in routes]),
        left=torch.stack([_pad(r.left, length) for r in routes]),
        right=torch.stack([_pad(r.right, length) for r in routes]),
        n_centre=torch.tensor([len(r.centre) for r in routes]),
        n_left=torch.tensor([len(r.left) for r in routes]),
        n_right=torch.tensor([len(r.right) for r in routes]),
        is_loop=torch.tensor([r.is_loop for r in routes]),
        entry=torch.stack([torch.stack([r.left[0], r.right[0]]) for r in routes]),
        exit=torch.stack([torch.stack([r.left[-1], r.right[-1]]) for r in routes]),
    )
    for name, value in vars(packed).items():
        setattr(packed, name, value.to(device))
    return packed


def load(map_file_path: Optional[str], n_extension: int, device) -> Tuple[Routes, float]:
    """The packed loop routes of map type "1" and the map's mean lane width [m]."""
    lanelets = parse_map(locate_map(map_file_path))
    routes = [build_route(loop_route(*spec), lanelets) for spec in LOOP_ROUTES]
    width = float(mean_lane_width(lanelets))
    if not math.isfinite(width):
        raise ValueError("road_traffic: the map's lane width is not finite")
    return pack_routes(routes, n_extension, device), width
