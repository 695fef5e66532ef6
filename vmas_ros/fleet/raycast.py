"""Laser scans by ray casting: every robot's rays against every other robot's disc and the arena walls.

Shapes: ``n`` scanning robots, ``R`` rays each, ``m`` discs. Rays start at the
robot's centre (a scanner mounted on the robot's axis) and its own disc is
not seen. The maths is whole-array, no loop over robots, rays or pairs:
``[n, R]`` for the walls, and for the discs one of two methods with the same
results (:func:`cast`): every ray against every disc (``[n, R, m]``, taken in
chunks of robots so the array stays a bounded size), or each disc against the
run of rays it spans (a flat array of (pair, ray) entries, much smaller once
a fleet is large). The tests check both against a ray-by-ray reference.

:func:`cast` gives true distances (``inf``: no hit at all); :func:`readings`
turns them into what a LaserScan carries, after REP 117: ``+inf`` for no
return within ``range_max``, ``-inf`` for a return closer than
``range_min``, ``NaN`` for a dropped (erroneous) reading, and Gaussian range
noise on the rest.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from vmas_ros.fleet.contacts import Arena

__all__ = ["ray_angles", "angle_increment", "cast", "readings", "CHUNK_ELEMENTS"]

#: the largest ``chunk * R * m`` array one pass of the disc test builds
CHUNK_ELEMENTS = 1 << 22


def angle_increment(n_rays: int, angle_min: float, angle_max: float) -> float:
    """LaserScan's ``angle_increment``: ``angle_max`` is the last ray's angle, not one past it."""
    return (angle_max - angle_min) / (n_rays - 1) if n_rays > 1 else 0.0


def ray_angles(n_rays: int, angle_min: float, angle_max: float) -> np.ndarray:
    """``[R]`` body-frame ray angles, the first at ``angle_min``, the last at ``angle_max``."""
    return angle_min + angle_increment(n_rays, angle_min, angle_max) * np.arange(n_rays)


def _disc_hits(origins: np.ndarray, directions: np.ndarray, centres: np.ndarray, radius: float,
               own: np.ndarray) -> np.ndarray:
    """``[k, R]`` distance along each ray to the nearest disc (``inf``: none).

    ``origins [k, 2]``, ``directions [k, R, 2]`` (unit), ``centres [m, 2]``,
    ``own [k]``: the index in ``centres`` of each robot's own disc, masked out.
    A ray starting inside a disc reads 0 (the disc covers the scanner).
    """
    rel = centres[None, :, :] - origins[:, None, :]  # [k, m, 2]
    along = np.einsum("krd,kmd->krm", directions, rel)  # [k, R, m]: distance to the closest approach
    squared = np.einsum("kmd,kmd->km", rel, rel)  # [k, m]
    squared[np.arange(len(origins)), own] = np.inf  # own disc: never hit
    half_chord_sq = radius * radius - (squared[:, None, :] - along * along)
    hit = half_chord_sq >= 0
    half_chord = np.sqrt(np.where(hit, half_chord_sq, 0.0))
    near, far = along - half_chord, along + half_chord
    distance = np.where(near >= 0, near, np.where(far >= 0, 0.0, np.inf))
    return np.where(hit, distance, np.inf).min(axis=2, initial=np.inf)


def _wall_hits(origins: np.ndarray, directions: np.ndarray, arena: Arena) -> np.ndarray:
    """``[n, R]`` distance along each ray to the arena's walls (``inf``: no walls that way)."""
    result = np.full(directions.shape[:2], np.inf)
    for axis, half in enumerate((arena.half_x, arena.half_y)):  # two axes, not robots: loop kept
        if not half:
            continue
        d = directions[..., axis]
        o = origins[:, axis][:, None]
        towards = np.abs(d) > 1e-12  # a ray parallel to these walls (cos(pi/2) is not 0) never meets them
        safe = np.where(towards, d, 1.0)
        t = np.where(towards, (np.where(d > 0, half, -half) - o) / safe, np.inf)
        result = np.minimum(result, np.where(t >= 0, t, 0.0))
    return result


def _span_hits(poses: np.ndarray, angles: np.ndarray, radius: float, max_range: float) -> np.ndarray:
    """``[n, R]`` distance along each ray to the nearest disc (``inf``: none), for evenly spaced ``angles``.

    Each pair (robot, disc) is tested only against the rays its disc spans:
    seen from a robot at distance ``d``, a disc covers the bearings within
    ``asin(radius / d)`` of its centre's, which on evenly spaced rays is a
    run of consecutive indices (one run per turn the scan makes). The runs
    of all pairs are laid end to end in one flat array, each entry gets the
    exact distance, and the nearest per ray is kept. Far fewer entries than
    ``n * R * m`` when discs look small, which they do in any fleet large
    enough for the count to matter. Discs wholly beyond ``max_range`` are
    left out.
    """
    n, n_rays = len(poses), len(angles)
    first, step = float(angles[0]), float(angles[1] - angles[0])
    result = np.full((n, n_rays), np.inf)
    gaps = poses[None, :, :2] - poses[:, None, :2]  # [n, m, 2] from robot i to disc j
    distance = np.hypot(gaps[..., 0], gaps[..., 1])
    np.fill_diagonal(distance, np.inf)  # own disc: never seen
    robot, disc = np.nonzero(distance - radius <= max_range)  # [P] pairs worth testing
    covered = distance[robot, disc] <= radius  # the scanner is inside that disc: every ray reads 0
    result[robot[covered]] = 0.0
    robot, disc = robot[~covered], disc[~covered]
    rel, d = gaps[robot, disc], distance[robot, disc]  # [P, 2], [P]
    half = np.arcsin(radius / d)  # [P] half the angle the disc spans
    centre = np.mod(np.arctan2(rel[:, 1], rel[:, 0]) - poses[robot, 2] - first, 2 * math.pi)  # [P] from ray 0
    turns = 2 * math.pi * np.arange(-1, int(step * (n_rays - 1) // (2 * math.pi)) + 2)  # [S] the scan's turns
    low = np.maximum(np.ceil((centre[:, None] - half[:, None] + turns) / step), 0).astype(np.int64)  # [P, S]
    high = np.minimum(np.floor((centre[:, None] + half[:, None] + turns) / step), n_rays - 1).astype(np.int64)
    count = np.maximum(high - low + 1, 0).ravel()  # [P * S] rays in each run
    run = np.repeat(np.arange(count.size), count)  # [E] the run of each entry
    ray = low.ravel()[run] + np.arange(run.size) - np.repeat(np.cumsum(count) - count, count)  # [E]
    pair = run // len(turns)  # [E]
    heading = poses[robot[pair], 2] + angles[ray]
    along = np.cos(heading) * rel[pair, 0] + np.sin(heading) * rel[pair, 1]
    half_chord_sq = radius * radius - (d[pair] ** 2 - along * along)
    hit = half_chord_sq >= 0  # a run's end ray may graze past by a rounding error
    t = along[hit] - np.sqrt(half_chord_sq[hit])
    np.minimum.at(result.reshape(-1), robot[pair][hit] * n_rays + ray[hit], t)
    return result


def _evenly_spaced(angles: np.ndarray) -> bool:
    if len(angles) < 2 or angles[1] <= angles[0]:
        return False
    return bool(np.allclose(np.diff(angles), angles[1] - angles[0], rtol=0.0, atol=1e-12))


def cast(poses: np.ndarray, angles: np.ndarray, radius: float, arena: Arena, max_range: float = math.inf,
         method: str = "auto", chunk_elements: int = CHUNK_ELEMENTS) -> np.ndarray:
    """True distances ``[n, R]`` from each robot along each ray to the first disc or wall (``inf``: none).

    Args:
        poses: ``[n, 3]`` x, y, yaw of the robots, which are also the discs seen.
        angles: ``[R]`` body-frame ray angles.
        radius: the discs' radius (m).
        arena: the walls (none when both half sizes are 0).
        max_range: distances beyond it may read ``inf`` (discs wholly beyond it are skipped).
        method: ``dense`` tests every ray against every disc (``[chunk, R, n]`` arrays, any angles);
            ``spans`` tests each disc against the rays it spans (evenly spaced angles only, far less
            work for a large fleet); ``auto``: spans where the angles allow.
        chunk_elements: bound of one ``[chunk, R, n]`` array of the dense method.
    """
    n = len(poses)
    origins = poses[:, :2]
    world = poses[:, 2:3] + angles[None, :]  # [n, R]
    directions = np.stack([np.cos(world), np.sin(world)], axis=-1)  # [n, R, 2]
    result = _wall_hits(origins, directions, arena)
    if n < 2:
        return result
    if method == "spans" or (method == "auto" and _evenly_spaced(angles)):
        return np.minimum(result, _span_hits(poses, angles, radius, max_range))
    chunk = max(1, chunk_elements // max(1, len(angles) * n))
    for start in range(0, n, chunk):
        rows = slice(start, start + chunk)
        hits = _disc_hits(origins[rows], directions[rows], origins, radius, np.arange(n)[rows])
        result[rows] = np.minimum(result[rows], hits)
    return result


def readings(distances: np.ndarray, range_min: float, range_max: float, noise: float = 0.0,
             dropout: float = 0.0, rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """LaserScan ranges ``[n, R]`` (float32) from true ``distances [n, R]``, after REP 117.

    A ray whose true distance is beyond ``range_max`` reads ``+inf``. Any other
    gets Gaussian noise of sigma ``noise``; a noisy value below ``range_min``
    then reads ``-inf`` and one above ``range_max`` ``+inf``. Each ray reads
    ``NaN`` with probability ``dropout``. ``rng`` draws the noise and the
    dropouts (needed when either is on).
    """
    ranges = np.array(distances, dtype=np.float64)
    seen = ranges <= range_max
    if noise > 0:
        ranges = np.where(seen, ranges + rng.normal(0.0, noise, ranges.shape), ranges)
    ranges = np.where(~seen | (ranges > range_max), math.inf, ranges)
    ranges = np.where(ranges < range_min, -math.inf, ranges)
    if dropout > 0:
        ranges = np.where(rng.random(ranges.shape) < dropout, math.nan, ranges)
    return ranges.astype(np.float32)
