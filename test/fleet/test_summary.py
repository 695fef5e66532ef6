"""The per-episode metrics and the summary file."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from test.fleet.helpers import episode
from vmas_ros.fleet.summary import EpisodeTracker, coverage, document, write_atomic


def test_time_to_goal_final_distance_and_all_reached():
    start = episode([[0, 0, 0], [5, 0, 0]], goals=[[1, 0], [5, 0.05]])
    tracker = EpisodeTracker(0, 0, start, goal_radius=0.1)
    zero = np.zeros(2, dtype=int)
    assert tracker.time_to_goal[1] == 0.0  # starts inside its goal radius
    for x in (0.5, 0.85, 0.95, 1.5):
        tracker.advance(0.5, np.array([[x, 0, 0], [5, 0, 0]]), zero, zero)
    record = tracker.record(np.array([[1.5, 0, 0], [5, 0, 0]]), "time")
    assert record["time_to_goal"] == [1.5, 0.0]
    assert record["all_reached_time"] == 1.5
    assert record["final_distance"] == pytest.approx([0.5, 0.05])
    assert record["duration"] == 2.0 and record["steps"] == 4 and record["ended_by"] == "time"


def test_a_robot_that_never_arrives_has_null_and_so_has_all_reached():
    tracker = EpisodeTracker(3, 1, episode([[0, 0, 0], [1, 0, 0]], goals=[[2, 0], [1, 0]]), 0.1)
    record = tracker.record(np.array([[0, 0, 0], [1, 0, 0]]), "reset")
    assert record["time_to_goal"] == [None, 0.0] and record["all_reached_time"] is None
    assert record["index"] == 3 and record["plan_index"] == 1


def test_landmark_goals_have_coverage_but_no_per_robot_metrics():
    tracker = EpisodeTracker(0, 0, episode([[0, 0, 0], [4, 0, 0]], goals=[[0, 1], [4, 0], [2, 0]]), 0.1)
    record = tracker.record(np.array([[0, 0, 0], [4, 0, 0]]), "time")
    assert record["time_to_goal"] is None and record["final_distance"] is None
    assert record["coverage"] == pytest.approx((1 + 0 + 2) / 3)


def test_coverage_and_min_separation_without_goals():
    assert coverage(np.zeros((2, 2)), np.zeros((0, 2))) is None
    tracker = EpisodeTracker(0, 0, episode([[0, 0, 0], [1, 0, 0], [3, 0, 0]]), 0.1)
    zero = np.zeros(3, dtype=int)
    tracker.advance(0.1, np.array([[0, 0, 0], [0.25, 0, 0], [3, 0, 0]]), zero, zero)
    tracker.advance(0.1, np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0]]), zero, zero)
    record = tracker.record(np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0]]), "time")
    assert record["min_separation"] == pytest.approx(0.25)
    assert record["coverage"] is None
    one = EpisodeTracker(0, 0, episode([[0, 0, 0]]), 0.1).record(np.zeros((1, 3)), "time")
    assert one["min_separation"] is None


def test_collisions_split_robots_and_walls():
    tracker = EpisodeTracker(0, 0, episode([[0, 0, 0], [1, 0, 0], [2, 0, 0]]), 0.1)
    pose = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=float)
    tracker.advance(0.1, pose, np.array([1, 1, 0]), np.array([0, 0, 2]))
    tracker.advance(0.1, pose, np.array([1, 2, 1]), np.array([0, 1, 0]))
    collisions = tracker.record(pose, "time")["collisions"]
    assert collisions == {"robot_robot": 3, "robot_wall": 3, "per_robot_robot": [2, 3, 1],
                          "per_robot_wall": [0, 1, 2]}


def test_a_record_is_strict_json():
    tracker = EpisodeTracker(0, 0, episode([[0, 0, 0], [1, 0, 0]], goals=[[5, 5], [6, 6]]), 0.1)
    doc = document({"scan_noise": 0.01}, ["a", "b"], 1, [tracker.record(np.zeros((2, 3)), "shutdown")], False)
    text = json.dumps(doc, allow_nan=False)
    assert json.loads(text)["episodes"][0]["all_reached_time"] is None
    assert not math.isnan(json.loads(text)["episodes"][0]["coverage"])


def test_write_atomic_replaces_the_file_and_keeps_the_old_one_on_failure(tmp_path):
    path = tmp_path / "deep" / "summary.json"
    write_atomic(str(path), {"episodes": [1]})
    write_atomic(str(path), {"episodes": [1, 2]})
    assert json.loads(path.read_text()) == {"episodes": [1, 2]}
    with pytest.raises(ValueError):
        write_atomic(str(path), {"episodes": [math.nan]})
    assert json.loads(path.read_text()) == {"episodes": [1, 2]}
    assert sorted(p.name for p in path.parent.iterdir()) == ["summary.json"]  # no temporary file left
