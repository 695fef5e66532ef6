"""``vmas-ros evaluate`` (vmas_ros.bench.heuristics): episode bookkeeping and the command's output."""
from __future__ import annotations

import csv

import torch

import vmas_ros
from vmas_ros import cli
from vmas_ros.bench.heuristics import episode_returns, evaluate_scenario, team_of
from vmas_ros.simulator.core import Agent, Sphere, World
from vmas_ros.simulator.scenario import BaseScenario


class CountdownScenario(BaseScenario):
    """Reward 1 per step for agent_0, 2 for agent_1; env i reports done from step i + 1 on."""

    def make_world(self, batch_dim, device, **kwargs):
        world = World(batch_dim, device)
        for i in range(2):
            world.add_agent(Agent(name=f"agent_{i}", shape=Sphere(0.05)))
        self.steps = torch.zeros(batch_dim, device=device)
        return world

    def reset_world_at(self, env_index=None):
        for agent in self.world.agents:
            agent.set_pos(torch.zeros(2, device=self.world.device), batch_index=env_index)
        if env_index is None:
            self.steps.zero_()
        else:
            self.steps[env_index] = 0

    def observation(self, agent):
        return agent.state.pos

    def reward(self, agent):
        if agent is self.world.agents[0]:
            self.steps += 1
        return torch.full_like(self.steps, 1.0 + self.world.agents.index(agent))

    def done(self):
        return self.steps >= torch.arange(1, self.world.batch_dim + 1, device=self.world.device)


def test_returns_stop_at_each_envs_first_done():
    env = vmas_ros.make_env(CountdownScenario(), num_envs=4, seed=0)
    returns, length, finished = episode_returns(env, None, max_steps=3)
    # env i is done after i + 1 steps (envs 3 never within 3 steps): rewards counted up to and incl. that step
    assert length.tolist() == [1, 2, 3, 3]
    assert finished.tolist() == [True, True, True, False]
    assert returns[0].tolist() == [1, 2, 3, 3] and returns[1].tolist() == [2, 4, 6, 6]


def test_team_names():
    assert team_of("adversary_2") == "adversary"
    assert team_of("agent 0") == "agent"
    assert team_of("alice") == "alice"
    assert team_of("agent_blue_10") == "agent_blue"


def test_heuristic_beats_random_on_simple_spread():
    heuristic, random = evaluate_scenario("simple_spread", num_envs=8, max_steps=40)
    assert (heuristic.policy, random.policy) == ("heuristic", "random")
    assert heuristic.mean_return > random.mean_return + 20
    assert heuristic.mean_episode_length == 40 and heuristic.done_fraction == 0


def test_command_writes_csv_and_markdown(tmp_path, capsys):
    out = tmp_path / "eval" / "heuristics"
    code = cli.main(["evaluate", "--scenarios", "simple_spread", "simple_tag", "--num-envs", "4",
                     "--max-steps", "10", "--out", str(out), "--quiet"])
    assert code == 0
    rows = list(csv.DictReader(out.with_suffix(".csv").open()))
    assert [(r["scenario"], r["policy"]) for r in rows] == [
        ("simple_spread", "heuristic"), ("simple_spread", "random"), ("simple_tag", "heuristic"), ("simple_tag", "random")]
    assert "adversary=" in rows[2]["team_returns"] and "agent=" in rows[2]["team_returns"]
    header, table = out.with_suffix(".md").read_text().split("\n\n", 1)
    assert header.startswith("Produced by `vmas-ros evaluate") and "torch " in header  # what made it, and where
    assert "| `simple_spread` |" in table and "| `simple_tag` |" in table
    assert table in capsys.readouterr().out


def test_command_rejects_bad_input(capsys):
    assert cli.main(["evaluate", "--scenarios", "simple_sprad", "--quiet"]) == 2
    assert "simple_sprad" in capsys.readouterr().err
    assert cli.main(["evaluate", "--scenarios", "simple", "--max-steps", "0", "--quiet"]) == 2
    assert "--max-steps" in capsys.readouterr().err


def test_zero_reward_worlds_are_scored_on_their_task():
    """diff_drive pays nothing; its heuristic drives home, which its task score (minus the distance) sees."""
    from vmas_ros.bench.heuristics import format_markdown
    from vmas_ros.scenarios import task_score

    heuristic, random = evaluate_scenario("diff_drive", num_envs=8, max_steps=60)
    assert heuristic.mean_return == random.mean_return == 0.0
    assert heuristic.task_score > random.task_score + 5, (heuristic.task_score, random.task_score)
    assert heuristic.task_score_name == "minus the mean distance to the origin [m]"
    table = format_markdown([heuristic, random])
    assert "| `diff_drive` | minus the mean distance to the origin [m] | " in table

    assert task_score("simple_spread") is None  # a real reward: no stand-in
    name, _, kwargs = task_score("pollock")
    assert kwargs == {"lidar": True} and "clearance" in name
