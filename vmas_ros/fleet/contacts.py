"""Robots are discs that cannot overlap, inside optional arena walls; contacts are counted at their onset.

After each integration step :func:`separate` moves the robots apart: every
overlapping pair is pushed apart along the line between their centres, each
by half the overlap (symmetric: neither robot is privileged), then robots are
put back inside the walls. Pushing one pair apart can press another together,
so the pass repeats (all pairs at once, as arrays ``[n, n]``) until nothing
overlaps or :data:`MAX_PASSES` is reached; a dense jam may keep a residue
smaller than the tolerance for a step or two, which the next steps remove.

What touches is judged on the positions the step produced, before they are
moved apart: two robots that keep pressing together stay in contact step
after step, and :class:`ContactCounter` counts one collision per contact
onset (a pair, or a robot and one wall, that did not touch the step before).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Tuple

import numpy as np

__all__ = ["Arena", "ContactCounter", "CONTACT_TOLERANCE", "MAX_PASSES", "pairwise_distance", "separate"]

#: robots (or a robot and a wall) this close count as touching, m: float noise on a resting contact
#: must not end it and start it again
CONTACT_TOLERANCE = 1e-6
#: separation passes per step at most
MAX_PASSES = 8


@dataclass(frozen=True)
class Arena:
    """Walls at x = +-``half_x`` and y = +-``half_y`` (m); 0 means no walls on that axis."""

    half_x: float = 0.0
    half_y: float = 0.0

    @property
    def halves(self) -> np.ndarray:
        """``[2]``: the half sizes, ``inf`` where there are no walls."""
        return np.array([self.half_x or np.inf, self.half_y or np.inf])

    @property
    def walled(self) -> bool:
        return bool(self.half_x or self.half_y)


def pairwise_distance(positions: np.ndarray) -> np.ndarray:
    """``[n, n]`` centre distances between ``positions [n, 2]``, ``inf`` on the diagonal."""
    gaps = positions[:, None, :] - positions[None, :, :]
    distance = np.sqrt(np.einsum("ijk,ijk->ij", gaps, gaps))
    np.fill_diagonal(distance, np.inf)
    return distance


def _push_apart(positions: np.ndarray, radius: float) -> Tuple[np.ndarray, float]:
    """One pass over all pairs: ``positions [n, 2]`` moved, and the deepest overlap found (m)."""
    n = len(positions)
    gaps = positions[:, None, :] - positions[None, :, :]  # [n, n, 2]: from j to i
    distance = np.sqrt(np.einsum("ijk,ijk->ij", gaps, gaps))
    overlap = 2 * radius - distance
    np.fill_diagonal(overlap, -np.inf)
    deepest = float(overlap.max()) if n > 1 else -np.inf
    if deepest <= 0:
        return positions, deepest
    # robots on the same spot have no line between them: the lower index goes to -x, the other to +x
    index = np.arange(n)
    fallback = np.where(index[:, None] < index[None, :], -1.0, 1.0)
    coincident = distance < 1e-12
    normal = np.where(coincident[..., None], 0.0, gaps / np.where(coincident, 1.0, distance)[..., None])
    normal[..., 0] += np.where(coincident, fallback, 0.0)
    push = np.clip(overlap, 0.0, None)[..., None] * 0.5 * normal  # [n, n, 2]
    return positions + push.sum(axis=1), deepest


def _inside(positions: np.ndarray, radius: float, arena: Arena) -> np.ndarray:
    """``positions [n, 2]`` with every disc moved inside the walls."""
    room = arena.halves - radius
    return np.clip(positions, -room, room)


def wall_contacts(positions: np.ndarray, radius: float, arena: Arena) -> np.ndarray:
    """``[n, 4]`` bool: disc touches the wall at -x, +x, -y, +y (nothing where there is no wall)."""
    room = arena.halves - radius - CONTACT_TOLERANCE
    return np.concatenate([positions <= -room, positions >= room], axis=1)[:, [0, 2, 1, 3]]


def separate(positions: np.ndarray, radius: float, arena: Arena) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Resolve overlaps after a step.

    Args:
        positions: ``[n, 2]`` centres after the step.
        radius: every robot's radius (m).
        arena: the walls.

    Returns:
        ``(positions [n, 2], touching [n, n] bool, at_wall [n, 4] bool)``: the
        centres moved apart and inside, which pairs touched and which walls each
        robot touched (judged on the input ``positions``).
    """
    touching = pairwise_distance(positions) < 2 * radius + CONTACT_TOLERANCE
    at_wall = wall_contacts(positions, radius, arena)
    out = _inside(positions, radius, arena)
    for _ in range(MAX_PASSES):
        out, deepest = _push_apart(out, radius)
        out = _inside(out, radius, arena)
        if deepest <= CONTACT_TOLERANCE * 1e-3:
            break
    return out, touching, at_wall


class ContactCounter:
    """Counts contact onsets from one step's ``touching [n, n]`` and ``at_wall [n, 4]`` to the next."""

    def __init__(self, touching: np.ndarray, at_wall: np.ndarray) -> None:
        self.touching, self.at_wall = touching.copy(), at_wall.copy()

    @classmethod
    def at(cls, positions: np.ndarray, radius: float, arena: Arena) -> "ContactCounter":
        """A counter whose "step before" is robots standing at ``positions [n, 2]`` (no onset for them)."""
        return cls(pairwise_distance(positions) < 2 * radius + CONTACT_TOLERANCE,
                   wall_contacts(positions, radius, arena))

    def update(self, touching: np.ndarray, at_wall: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """``(robot_onsets [n], wall_onsets [n])``: per robot, the new contacts with robots and with walls.

        A pair's onset counts for both robots of the pair: the fleet's number of
        robot-robot collisions is ``robot_onsets.sum() // 2``.
        """
        new_pairs = touching & ~self.touching
        new_walls = at_wall & ~self.at_wall
        self.touching, self.at_wall = touching.copy(), at_wall.copy()
        return new_pairs.sum(axis=1), new_walls.sum(axis=1)
