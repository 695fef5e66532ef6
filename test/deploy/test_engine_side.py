"""deploy-eval's engine side and report: start states the fleet can replay, and metrics measured as the
fleet measures them."""
from __future__ import annotations

import numpy as np
import pytest

from vmas_ros.deploy import engine_side, report
from vmas_ros.deploy.cli import fleet_starts, parse_params, parse_seeds


class Still:
    """An OnnxPolicy stand-in: zero actions of the right shape."""

    def act(self, observation: np.ndarray) -> np.ndarray:
        return np.zeros(observation.shape[:2] + (2,), dtype=np.float32)


class SeekGoal:
    """Navigation: push towards the own goal (observation columns 4:6 hold position minus goal)."""

    def act(self, observation: np.ndarray) -> np.ndarray:
        return np.clip(-3.0 * observation[..., 4:6] - observation[..., 2:4], -1, 1).astype(np.float32)


def test_simple_spread_starts_are_apart_and_coverage_is_the_mean_nearest_distance():
    result = engine_side.engine_episodes(Still(), "simple_spread", {}, episodes=3, seed=4, seconds=0.5)
    assert len(result["starts"]) == len(result["episodes"]) == 3 and not result["per_robot_goals"]
    assert result["radius"] == pytest.approx(0.15) and result["steps"] == 5
    for start, episode in zip(result["starts"], result["episodes"]):
        robots, goals = np.array(start["robots"]), np.array(start["goals"])
        assert robots.shape == (3, 3) and goals.shape == (3, 2)
        gaps = np.linalg.norm(robots[:, None, :2] - robots[None, :, :2], axis=-1) + np.eye(3) * 9
        assert gaps.min() >= 0.3, "robots of radius 0.15 must start apart"
        # standing still: the end is the start
        expected = np.linalg.norm(goals[:, None] - robots[None, :, :2], axis=-1).min(axis=1).mean()
        assert episode["coverage"] == pytest.approx(expected, abs=1e-5)
    assert [e["env_index"] for e in result["episodes"]] == sorted(e["env_index"] for e in result["episodes"])


def test_navigation_goals_are_per_robot_and_done_times_follow_the_env():
    result = engine_side.engine_episodes(SeekGoal(), "navigation", {"n_agents": 2}, episodes=2, seed=0, seconds=12.0)
    assert result["per_robot_goals"] and result["goal_radius"] == pytest.approx(0.1)
    for episode in result["episodes"]:
        assert episode["all_at_goal_time"] is not None, episode
        assert episode["all_reached_time"] <= episode["all_at_goal_time"] + 1e-9
        assert max(episode["time_to_goal"]) == pytest.approx(episode["all_reached_time"])
        assert all(d < 0.2 for d in episode["final_distance"])


def test_end_at_done_cuts_each_episode_where_every_robot_first_stands_on_its_goal():
    whole = engine_side.engine_episodes(SeekGoal(), "navigation", {"n_agents": 2}, episodes=2, seed=0, seconds=12.0)
    cut = engine_side.engine_episodes(SeekGoal(), "navigation", {"n_agents": 2}, episodes=2, seed=0, seconds=12.0,
                                      end_at_done=True)
    assert whole["starts"] == cut["starts"]
    for full, short in zip(whole["episodes"], cut["episodes"]):
        assert short["all_at_goal_time"] == pytest.approx(full["all_at_goal_time"]) == short["duration"]
        assert full["duration"] == pytest.approx(12.0)
        assert all(d <= 0.1 for d in short["final_distance"]), "the cut lands on the first done step"
        assert short["robot_robot"] <= full["robot_robot"]


def test_each_contact_counts_once_when_it_begins():
    """Two robots of radius 0.1 along x: they meet, stay in contact, part, and meet again: two onsets."""
    gaps = [1.0, 0.5, 0.19, 0.15, 0.18, 0.25, 0.19, 0.5]
    track = np.zeros((len(gaps), 1, 2, 2))
    track[:, 0, 1, 0] = gaps
    onsets, separation = engine_side.contact_onsets(track, 0.1)
    assert onsets.tolist() == [2] and separation[0] == pytest.approx(0.15)


def test_robots_driven_into_each_other_collide_in_the_engine():
    class Collide:
        def act(self, observation):
            pos = observation[..., 0:2]  # each agent's own position; the other agent's is the other row
            return np.clip(5.0 * (pos[:, ::-1] - pos), -1, 1).astype(np.float32)

    result = engine_side.engine_episodes(Collide(), "navigation", {"n_agents": 2}, episodes=2, seed=1, seconds=6.0)
    assert all(e["robot_robot"] >= 1 and e["min_separation"] < 0.2 for e in result["episodes"]), result["episodes"]
    calm = engine_side.engine_episodes(Still(), "navigation", {"n_agents": 2}, episodes=2, seed=1, seconds=1.0)
    assert all(e["robot_robot"] == 0 for e in calm["episodes"])


def test_fleet_headings_are_random_only_where_the_agents_never_turn():
    rng = np.random.default_rng(0)
    still = [{"robots": [[0, 0, 0.0], [1, 0, 0.0]], "goals": []}]
    turned = fleet_starts(still, "auto", rng)[0]["robots"]
    assert len({round(r[2], 6) for r in turned}) == 2 and all(-np.pi <= r[2] < np.pi for r in turned)
    moving = [{"robots": [[0, 0, 0.5], [1, 0, -1.0]], "goals": []}]
    assert fleet_starts(moving, "auto", rng)[0]["robots"] == [[0, 0, 0.5], [1, 0, -1.0]]
    assert fleet_starts(moving, "engine", rng) == moving
    assert fleet_starts(still, "engine", rng) == still


@pytest.mark.parametrize("text,seeds", [("0..4", [0, 1, 2, 3, 4]), ("3,7", [3, 7]), ("5", [5])])
def test_seeds_parse(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize("text", ["a..b", "", "-1"])
def test_bad_seeds_are_refused_by_value(text):
    with pytest.raises(ValueError, match="--seeds"):
        parse_seeds(text)


def test_params_take_yaml_values_and_refuse_other_forms():
    assert parse_params(["lookahead:=0.2", "adapter:=navigation", "x:=true"], "--p") == \
        {"lookahead": 0.2, "adapter": "navigation", "x": True}
    with pytest.raises(ValueError, match="--policy-param must be NAME:=VALUE, got 'lookahead=0.2'"):
        parse_params(["lookahead=0.2"], "--policy-param")


def test_the_report_pairs_episodes_by_their_start_and_totals_them():
    engine = {"per_robot_goals": True, "episodes": [
        {"coverage": 0.2, "robot_robot": 0, "all_at_goal_time": 3.0},
        {"coverage": 0.4, "robot_robot": 1, "all_at_goal_time": None}]}
    fleet = {"episodes": [  # the fleet ran them in another order, and was stopped during a repeat
        {"plan_index": 1, "ended_by": "time", "coverage": 0.5, "collisions": {"robot_robot": 2}, "all_at_goal_time": 9.0},
        {"plan_index": 0, "ended_by": "time", "coverage": 0.3, "collisions": {"robot_robot": 0}, "all_at_goal_time": 4.0},
        {"plan_index": 0, "ended_by": "shutdown", "coverage": 9.0, "collisions": {"robot_robot": 9},
         "all_at_goal_time": None}]}
    rows = report.pair_episodes(engine, fleet, ["a", "b"])
    assert [(r["episode"], r["fleet_coverage"], r["fleet_time"]) for r in rows] == [("a", 0.3, 4.0), ("b", 0.5, 9.0)]
    found = report.totals(rows, True)
    assert found["coverage_ratio"] == pytest.approx(0.4 / 0.3)
    assert found["engine_success_rate"] == 0.5 and found["fleet_success_rate"] == 1.0
    assert found["fleet_time_to_goal"] == pytest.approx(6.5) and found["fleet_collisions_per_episode"] == 1.0
    text = report.markdown(rows, found, True, {"policy": "p.json", "scenario": "navigation", "scenario_kwargs": "{}",
                                               "command": "vmas-ros deploy-eval ...", "fleet": {"command_latency": 0.05},
                                               "policy_node": "adapter navigation"})
    assert "| b | 0.400 | 0.500 | 1.25 | never | 9.0 | 1 | 2 |" in text and "command_latency 0.05" in text
