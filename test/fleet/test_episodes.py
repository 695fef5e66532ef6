"""Episodes files and start poses: what loads, and every refusal naming the bad value and what was expected."""
from __future__ import annotations

import json

import numpy as np
import pytest

from test.fleet.helpers import params
from vmas_ros.fleet.contacts import Arena
from vmas_ros.fleet.episodes import check, episode_from, line_up, load_file, plan

GOOD = {"episodes": [
    {"robots": [[0, 0, 0], [1, 0, 1.5]], "goals": [[2, 0], [2, 1]]},
    {"robots": [[0, 1, 0], [1, 1, 0]], "goals": [[0, 0]]},  # a landmark to cover
    {"robots": [[0, 2, 0], [1, 2, -3]]},                    # no goals
]}


def write(tmp_path, data, suffix=".yaml") -> str:
    path = tmp_path / f"episodes{suffix}"
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return str(path)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_a_good_file_loads(tmp_path, suffix):
    episodes = load_file(write(tmp_path, GOOD, suffix))
    assert [e.robots.shape for e in episodes] == [(2, 3)] * 3
    assert [e.goals.shape for e in episodes] == [(2, 2), (1, 2), (0, 2)]
    assert [e.per_robot_goals for e in episodes] == [True, False, False]
    assert episodes[0].robots[1].tolist() == [1.0, 0.0, 1.5]


def test_yaml_block_style_loads(tmp_path):
    text = "episodes:\n  - robots:\n      - [0, 0, 0]\n      - [1, 0, 0]\n    goals: [[1, 1], [2, 2]]\n"
    assert load_file(write(tmp_path, text))[0].goals.tolist() == [[1.0, 1.0], [2.0, 2.0]]


@pytest.mark.parametrize("data, words", [
    ("[1, 2]", ["must be a mapping with a list 'episodes'"]),
    ({"episode": []}, ["must be a mapping with a list 'episodes'"]),
    ({"episodes": []}, ["non-empty list"]),
    ({"episodes": [], "extra": 1}, ["unknown keys ['extra']"]),
    ({"episodes": [[0, 0, 0]]}, ["episodes[0] must be a mapping"]),
    ({"episodes": [{"goals": [[0, 0]]}]}, ["episodes[0] lacks robots"]),
    ({"episodes": [{"robots": [[0, 0, 0], [1, 0]]}]}, ["episodes[0].robots[1] must be [x, y, yaw]", "[1, 0]"]),
    ({"episodes": [{"robots": [[0, 0, 0], [1, 0, "a"]]}]}, ["episodes[0].robots[1]", "3 numbers"]),
    ({"episodes": [{"robots": [[0, 0, 0], [1, 0, True]]}]}, ["episodes[0].robots[1]", "3 numbers"]),
    ({"episodes": [{"robots": [[0, 0, 0], [1, 0, 0]], "goals": [[1, 2, 3]]}]}, ["episodes[0].goals[0] must be [x, y]"]),
    ({"episodes": [{"robots": [[0, 0, 0], [1, 0, 0]], "goals": 5}]}, ["episodes[0].goals must be a list"]),
    ({"episodes": [{"robots": [[0, 0, 0], [1, 0, 0]], "speed": 2}]}, ["unknown keys ['speed']", "expected robots"]),
    ("episodes:\n  - robots: [[0, 0, .nan], [1, 0, 0]]\n", ["episodes[0].robots[0] must hold finite numbers"]),
    ("episodes: [robots: [[0, 0", ["is not valid YAML"]),
])
def test_malformed_files_are_refused_with_the_place_and_the_form(tmp_path, data, words):
    with pytest.raises(ValueError) as refused:
        load_file(write(tmp_path, data))
    assert all(word in str(refused.value) for word in words), str(refused.value)


def test_non_finite_json_and_broken_json_are_refused(tmp_path):
    path = tmp_path / "e.json"
    path.write_text('{"episodes": [{"robots": [[0, 0, 0], [1, Infinity, 0]]}]}')
    with pytest.raises(ValueError, match=r"robots\[1\] must hold finite numbers"):
        load_file(str(path))
    path.write_text('{"episodes": [')
    with pytest.raises(ValueError, match="is not valid JSON"):
        load_file(str(path))


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(ValueError, match="cannot be read"):
        load_file(str(tmp_path / "none.yaml"))


def ep(robots, goals=()):
    return episode_from({"robots": robots, "goals": [list(g) for g in goals]}, "start_poses")


@pytest.mark.parametrize("episode, n, arena, words", [
    (ep([[0, 0, 0]]), 2, Arena(), ["start_poses has 1 robots, n_robots is 2"]),
    (ep([[0, 0, 0], [0.15, 0, 0]]), 2, Arena(), ["robots 0 at [0.0, 0.0] and 1 at [0.15, 0.0] overlap", ">= 0.2 m"]),
    (ep([[0, 0, 0], [0.95, 0, 0]]), 2, Arena(1.0, 1.0), ["robot 1 at [0.95, 0.0] is not inside the walls",
                                                       "|x| <= 0.9"]),
    (ep([[0, 0, 0], [0.5, 0, 0]], [[0, 1.5]]), 2, Arena(1.0, 1.0), ["goal 0 at [0.0, 1.5] is outside the walls"]),
])
def test_episodes_the_fleet_cannot_start_are_refused(episode, n, arena, words):
    with pytest.raises(ValueError) as refused:
        check(episode, n, 0.1, arena, "start_poses")
    assert all(word in str(refused.value) for word in words), str(refused.value)


def test_touching_starts_are_allowed():
    check(ep([[0, 0, 0], [0.2, 0, 0]]), 2, 0.1, Arena(), "start_poses")
    check(ep([[0.9, 0, 0], [-0.9, 0, 0]]), 2, 0.1, Arena(1.0, 1.0), "start_poses")


def test_the_default_start_is_a_line_without_goals():
    episode = line_up(4, 0.1, Arena())
    assert episode.robots[:, 1].tolist() == pytest.approx([-0.6, -0.2, 0.2, 0.6])
    assert (episode.robots[:, [0, 2]] == 0).all() and len(episode.goals) == 0  # side by side, facing +x
    with pytest.raises(ValueError, match="need arena_half_y >= 0.7"):
        line_up(4, 0.1, Arena(0.5, 0.5))


def test_plan_reads_the_source_the_parameters_name(tmp_path):
    assert len(plan(params(n_robots=2, episodes_file=write(tmp_path, GOOD)))) == 3
    one = plan(params(n_robots=2, start_poses="{robots: [[0, 0, 0], [1, 0, 0]], goals: [[3, 3]]}"))
    assert len(one) == 1 and one[0].goals.tolist() == [[3.0, 3.0]]
    assert plan(params(n_robots=5))[0].robots.shape == (5, 3)
    with pytest.raises(ValueError, match=r"episodes_file .*episodes\[0\] has 2 robots, n_robots is 3"):
        plan(params(n_robots=3, episodes_file=write(tmp_path, GOOD)))
    with pytest.raises(ValueError, match="start_poses: robots 0 at"):
        plan(params(n_robots=2, start_poses="{robots: [[0, 0, 0], [0, 0, 0]]}"))
    assert np.isfinite(plan(params())[0].robots).all()
