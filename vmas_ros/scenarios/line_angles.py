"""VMAS's angle helpers under its names, as its line and wind scenarios export them.

``from vmas.scenarios.joint_passage import get_line_angle_0_90`` and the like
keep working: asym_joint, joint_passage, joint_passage_size and
wind_flocking re-export these. A line's angle is undirected (``a`` and
``a + pi`` are the same line); a heading's is not.
"""
from __future__ import annotations

import math

from torch import Tensor

from vmas_ros.scenarios.joint_passage_common import direction, heading_gap, line_angle_gap

__all__ = ["angle_to_vector", "get_line_angle_0_90", "get_line_angle_0_180", "get_line_angle_dist_0_180",
           "get_line_angle_dist_0_360"]


def angle_to_vector(angle: Tensor) -> Tensor:
    """Unit vectors ``[B, 2]`` of angles ``[B, 1]``."""
    return direction(angle)


def get_line_angle_0_180(rot: Tensor) -> Tensor:
    """A line's angle in ``[0, pi)`` (same shape)."""
    return rot % math.pi


def get_line_angle_0_90(rot: Tensor) -> Tensor:
    """The angle in ``[0, pi/2]`` between a line at ``rot`` and the x axis (same shape)."""
    folded = rot % math.pi
    return (math.pi - folded).minimum(folded)


def get_line_angle_dist_0_180(angle: Tensor, goal: Tensor) -> Tensor:
    """The angle in ``[0, pi/2]`` between two lines at ``angle`` and ``goal`` (``[B, 1]`` each): ``[B]``."""
    return line_angle_gap(angle, goal)


def get_line_angle_dist_0_360(angle: Tensor, goal: Tensor) -> Tensor:
    """Minus the cosine between two headings (``[B, 1]`` each): ``[B]``, -1 when they agree."""
    return heading_gap(angle, goal)
