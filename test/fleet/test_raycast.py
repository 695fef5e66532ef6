"""Ray casting against discs and walls, and LaserScan readings after REP 117."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vmas_ros.fleet.contacts import Arena
from vmas_ros.fleet.raycast import angle_increment, cast, ray_angles, readings

R = 0.1
NO_WALLS = Arena()


def reference(poses, angles, radius, arena) -> np.ndarray:
    """One ray at a time in plain Python: the quadratic of a ray and a circle, and the four wall lines."""
    out = np.full((len(poses), len(angles)), math.inf)
    for i, (x, y, yaw) in enumerate(poses):
        for k, angle in enumerate(angles):
            dx, dy = math.cos(yaw + angle), math.sin(yaw + angle)
            best = math.inf
            for j, (cx, cy, _) in enumerate(poses):
                if j == i:
                    continue
                fx, fy = x - cx, y - cy
                b = fx * dx + fy * dy
                c = fx * fx + fy * fy - radius * radius
                disc = b * b - c
                if disc < 0:
                    continue
                for t in (-b - math.sqrt(disc), -b + math.sqrt(disc)):
                    if t >= 0:
                        best = min(best, t)
                        break
            for half, o, d in ((arena.half_x, x, dx), (arena.half_y, y, dy)):
                if half and d:
                    best = min(best, ((half if d > 0 else -half) - o) / d)
            out[i, k] = best
    return out


def test_ray_angles_end_on_angle_max():
    angles = ray_angles(360, -math.pi, math.pi - 2 * math.pi / 360)
    assert angles[0] == -math.pi and angles[-1] == pytest.approx(math.pi - 2 * math.pi / 360)
    assert angle_increment(360, -math.pi, math.pi - 2 * math.pi / 360) == pytest.approx(2 * math.pi / 360)
    assert ray_angles(1, 0.3, 0.3).tolist() == [0.3]


def test_a_disc_straight_ahead_and_off_axis():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [-3.0, 0.05, 0.0]])
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
    d = cast(poses, angles, R, NO_WALLS)
    assert d[0, 0] == pytest.approx(1.0 - R)                               # centre on the ray
    assert d[0, 1] == pytest.approx(2.0 - R)
    assert d[0, 2] == pytest.approx(3.0 - math.sqrt(R * R - 0.05 ** 2))    # 5 cm off the ray
    assert d[0, 3] == math.inf                                             # nothing that way


def test_the_rays_turn_with_the_robot():
    poses = np.array([[0.0, 0.0, math.pi / 2], [1.0, 0.0, 0.0]])
    d = cast(poses, np.array([0.0, -math.pi / 2]), R, NO_WALLS)
    assert d[0, 0] == math.inf
    assert d[0, 1] == pytest.approx(1.0 - R)  # the other robot is on the right of a robot facing +y


def test_a_disc_beside_the_ray_is_missed_and_the_own_disc_is_never_seen():
    poses = np.array([[0.0, 0.0, 0.0], [2.0, R + 1e-6, 0.0]])
    assert cast(poses, np.array([0.0]), R, NO_WALLS)[0, 0] == math.inf
    alone = cast(np.array([[0.3, -0.2, 1.0]]), ray_angles(36, -math.pi, math.pi), R, NO_WALLS)
    assert np.isinf(alone).all()


def test_walls_analytic():
    arena = Arena(2.0, 1.0)
    d = cast(np.array([[0.5, 0.0, 0.0]]), np.array([0.0, math.pi / 2, math.pi, math.pi / 4, -math.pi / 2]),
             R, arena)
    assert d[0] == pytest.approx([1.5, 1.0, 2.5, math.sqrt(2), 1.0])
    # walls on one axis only: the other axis is open
    d = cast(np.array([[0.0, 0.0, 0.0]]), np.array([0.0, math.pi / 2]), R, Arena(half_x=2.0))
    assert d[0, 0] == pytest.approx(2.0) and d[0, 1] == math.inf


def test_the_nearest_of_a_disc_and_a_wall_wins():
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert cast(poses, np.array([0.0]), R, Arena(3.0, 3.0))[0, 0] == pytest.approx(0.9)
    assert cast(poses, np.array([0.0]), R, Arena(0.5, 3.0))[0, 0] == pytest.approx(0.5)


def scattered(seed: int, count: int = 6, radius: float = 0.3) -> np.ndarray:
    """``[count, 3]`` random poses of robots that do not overlap (as the fleet keeps them)."""
    rng = np.random.default_rng(seed)
    poses = np.zeros((0, 3))
    while len(poses) < count:
        candidate = [rng.uniform(-2.5, 2.5), rng.uniform(-1.5, 1.5), rng.uniform(-4, 4)]
        if all(math.dist(candidate[:2], p[:2]) >= 2 * radius for p in poses):
            poses = np.vstack([poses, candidate])
    return poses


FIELDS_OF_VIEW = {
    "full circle": (72, -math.pi, math.pi - 2 * math.pi / 72),
    "front half": (31, -math.pi / 2, math.pi / 2),
    "odd increment": (50, -1.0, 2.5),            # 2 pi is no whole number of increments
    "two turns": (100, -2 * math.pi, 2 * math.pi),  # every bearing seen twice
}


@pytest.mark.parametrize("method", ["dense", "spans"])
@pytest.mark.parametrize("field", sorted(FIELDS_OF_VIEW))
@pytest.mark.parametrize("seed", range(3))
def test_both_methods_match_a_ray_by_ray_reference(seed, field, method):
    arena = Arena(3.0, 2.0)
    poses = scattered(seed)
    angles = ray_angles(*FIELDS_OF_VIEW[field])
    expected = reference(poses, angles, 0.3, arena)
    assert cast(poses, angles, 0.3, arena, method=method) == pytest.approx(expected, rel=1e-9, abs=1e-9)
    if method == "dense":  # taken in chunks of robots, the same numbers
        chunked = cast(poses, angles, 0.3, arena, method="dense", chunk_elements=100)
        assert chunked == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_a_large_fleet_gives_the_same_scans_either_way():
    poses = scattered(9, count=60, radius=0.1)
    angles = ray_angles(360, -math.pi, math.pi - 2 * math.pi / 360)
    dense = cast(poses, angles, 0.1, Arena(), method="dense")
    assert cast(poses, angles, 0.1, Arena(), method="spans") == pytest.approx(dense, rel=1e-9, abs=1e-9)
    # leaving out the discs beyond the scanner's range changes no reading within it
    near = cast(poses, angles, 0.1, Arena(), max_range=1.0)
    within = dense <= 1.0
    assert near[within] == pytest.approx(dense[within], rel=1e-9, abs=1e-9) and (near[~within] > 1.0).all()


@pytest.mark.parametrize("method", ["dense", "spans"])
def test_a_scanner_inside_another_disc_reads_zero(method):
    poses = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0]])
    angles = ray_angles(8, -math.pi, math.pi - math.pi / 4)
    assert (cast(poses, angles, R, NO_WALLS, method=method) == 0.0).all()


def test_readings_follow_rep_117():
    distances = np.array([[0.05, 0.12, 1.0, 3.5, 3.6, math.inf]])
    ranges = readings(distances, 0.12, 3.5)
    assert ranges.dtype == np.float32
    assert ranges[0, 0] == -math.inf                 # closer than range_min
    assert ranges[0, 1:4].tolist() == pytest.approx([0.12, 1.0, 3.5])
    assert ranges[0, 4] == math.inf and ranges[0, 5] == math.inf  # nothing within range_max


def test_two_touching_robots_read_minus_inf():
    poses = np.array([[0.0, 0.0, 0.0], [2 * R, 0.0, 0.0]])
    ranges = readings(cast(poses, np.array([0.0]), R, NO_WALLS), 0.12, 3.5)
    assert ranges[0, 0] == -math.inf


def test_dropout_rate_and_noise_sigma():
    rng = np.random.default_rng(3)
    ranges = readings(np.full((100, 1000), 2.0), 0.12, 3.5, dropout=0.25, rng=rng)
    assert np.isnan(ranges).mean() == pytest.approx(0.25, abs=0.01)
    assert (ranges[~np.isnan(ranges)] == 2.0).all()
    noisy = readings(np.full((100, 1000), 2.0), 0.12, 3.5, noise=0.05, rng=rng)
    assert noisy.mean() == pytest.approx(2.0, abs=0.001)
    assert noisy.std() == pytest.approx(0.05, rel=0.02)
    # a ray that hits nothing stays +inf with noise on
    assert np.isposinf(readings(np.full((1, 50), math.inf), 0.12, 3.5, noise=0.05, rng=rng)).all()


def test_noise_is_reproducible_from_the_seed():
    a = readings(np.full((3, 10), 1.0), 0.12, 3.5, 0.1, 0.1, np.random.default_rng(7))
    b = readings(np.full((3, 10), 1.0), 0.12, 3.5, 0.1, 0.1, np.random.default_rng(7))
    assert np.array_equal(a, b, equal_nan=True)
