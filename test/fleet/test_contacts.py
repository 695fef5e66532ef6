"""Discs that cannot overlap, walls that hold them, and collisions counted at their onset."""
from __future__ import annotations

import numpy as np
import pytest

from vmas_ros.fleet.contacts import Arena, ContactCounter, pairwise_distance, separate

R = 0.1


def test_an_overlapping_pair_is_pushed_apart_symmetrically():
    out, touching, at_wall = separate(np.array([[0.0, 0.0], [0.15, 0.0], [5.0, 5.0]]), R, Arena())
    assert out == pytest.approx(np.array([[-0.025, 0.0], [0.175, 0.0], [5.0, 5.0]]))
    assert touching[0, 1] and touching[1, 0] and not touching[0, 2] and not touching.diagonal().any()
    assert not at_wall.any()


def test_robots_on_the_same_spot_are_separated():
    out, touching, _ = separate(np.array([[1.0, 1.0], [1.0, 1.0]]), R, Arena())
    assert pairwise_distance(out)[0, 1] == pytest.approx(2 * R)
    assert out.mean(axis=0) == pytest.approx([1.0, 1.0])
    assert touching[0, 1]


def test_a_jam_is_resolved_inside_the_walls():
    rng = np.random.default_rng(0)
    positions = rng.uniform(-0.3, 0.3, size=(12, 2))
    arena = Arena(1.0, 1.0)
    for _ in range(5):  # a dense jam may need a few steps
        positions, _, _ = separate(positions, R, arena)
    assert pairwise_distance(positions).min() >= 2 * R - 1e-6
    assert (np.abs(positions) <= 1.0 - R + 1e-12).all()


def test_walls_hold_robots_and_report_which_wall():
    arena = Arena(2.0, 1.0)
    out, _, at_wall = separate(np.array([[1.95, 0.0], [0.0, -1.5], [0.0, 0.0]]), R, arena)
    assert out == pytest.approx(np.array([[1.9, 0.0], [0.0, -0.9], [0.0, 0.0]]))
    assert at_wall.tolist() == [[False, True, False, False], [False, False, True, False], [False] * 4]
    # no walls on an axis of half size 0
    out, _, at_wall = separate(np.array([[100.0, 0.5]]), R, Arena(half_y=1.0))
    assert out.tolist() == [[100.0, 0.5]] and not at_wall.any()


def test_a_collision_counts_once_however_long_the_contact_lasts():
    arena = Arena(1.0, 1.0)
    apart = np.array([[0.0, 0.0], [0.5, 0.0]])
    counter = ContactCounter.at(apart, R, arena)
    onsets = []
    # approach, press together for three steps, back off, touch again
    for x in (0.3, 0.15, 0.1, 0.1, 0.5, 0.19):
        _, touching, at_wall = separate(np.array([[0.0, 0.0], [x, 0.0]]), R, arena)
        robots, walls = counter.update(touching, at_wall)
        onsets.append(robots.tolist())
    assert onsets == [[0, 0], [1, 1], [0, 0], [0, 0], [0, 0], [1, 1]]


def test_wall_contact_onsets_per_robot():
    arena = Arena(1.0, 1.0)
    counter = ContactCounter.at(np.array([[0.0, 0.0]]), R, arena)
    counts = []
    for x in (0.5, 0.95, 0.95, 0.5, 0.9):  # 0.9 is exactly touching: a contact too
        _, touching, at_wall = separate(np.array([[x, 0.0]]), R, arena)
        counts.append(int(counter.update(touching, at_wall)[1][0]))
    assert counts == [0, 1, 0, 0, 1]


def test_starting_in_contact_is_no_onset():
    positions = np.array([[0.0, 0.0], [2 * R, 0.0]])
    counter = ContactCounter.at(positions, R, Arena())
    _, touching, at_wall = separate(positions, R, Arena())
    robots, _ = counter.update(touching, at_wall)
    assert robots.tolist() == [0, 0]
