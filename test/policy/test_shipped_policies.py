"""The policies shipped under ``policies/``: each loads, matches its JSON and the env it names, and does its task.

Every ``policies/*.json`` is checked, so a policy added without a recipe,
or a recipe changed without training its policy again, fails here: the
JSON must name the scenario and kwargs of the recipe in ``config/train/``
of the same stem, and the ONNX file's sizes must be the env's.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

import vmas_ros
from vmas_ros.deploy import engine_side
from vmas_ros.policy.onnx_policy import OnnxPolicy

REPO = Path(__file__).resolve().parents[2]
SHIPPED = sorted((REPO / "policies").glob("*.json"))
NAVIGATION = [path for path in SHIPPED if path.stem.startswith("navigation")]


def recipe_of(path: Path) -> dict:
    return yaml.safe_load((REPO / "config" / "train" / f"{path.stem}.yaml").read_text())


def test_every_recipe_has_its_shipped_policy():
    recipes = sorted(p.stem for p in (REPO / "config" / "train").glob("*.yaml"))
    assert [p.stem for p in SHIPPED] == recipes


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_a_shipped_policy_loads_and_matches_its_recipe_and_env(path):
    policy = OnnxPolicy.load(path)  # checks the ONNX file's checksum and graph against the JSON
    recipe = recipe_of(path)
    meta = policy.metadata
    assert meta["scenario"] == recipe["scenario"] and meta["scenario_kwargs"] == recipe["scenario_kwargs"]
    assert meta["algorithm"] == recipe["algorithm"]
    wanted = recipe.get("randomisation", {})
    for setting, drawn in meta["randomisation"].items():  # the recipe's ranges; every other setting fixed
        assert drawn == wanted[setting] if setting in wanted else drawn[0] == drawn[1], (setting, drawn)
    assert set(wanted) <= set(meta["randomisation"])
    env = vmas_ros.make_env(meta["scenario"], num_envs=8, seed=0, **meta["scenario_kwargs"])
    assert [agent.name for agent in env.world.agents] == policy.agents
    observations = env.reset()
    assert [o.shape[-1] for o in observations] == [policy.observation_size] * len(policy.agents)
    spaces = [space.shape[0] for space in env.action_space]
    assert spaces == [policy.action_size] * len(policy.agents)
    actions = policy.act(torch.stack(observations, dim=1).numpy())
    assert actions.shape == (8, len(policy.agents), policy.action_size) and np.isfinite(actions).all()
    assert (actions >= policy.action_low - 1e-6).all() and (actions <= policy.action_high + 1e-6).all()


@pytest.mark.parametrize("path", NAVIGATION, ids=lambda p: p.stem)
def test_a_shipped_navigation_policy_brings_every_agent_to_its_goal_in_the_engine(path):
    """Success: every agent on its goal at once (the env's ``done``) before the recipe's ``max_steps``.
    docs/bench/deploy.md measures it over 100 episodes; here 20, from other seeds."""
    policy = OnnxPolicy.load(path)
    recipe = recipe_of(path)
    dt = vmas_ros.make_env(recipe["scenario"], num_envs=1, **recipe["scenario_kwargs"]).world.dt
    seconds = recipe["max_steps"] * dt
    done = 0
    for seed in (101, 102):
        part = engine_side.engine_episodes(policy, recipe["scenario"], recipe["scenario_kwargs"], 10, seed, seconds)
        done += sum(e["all_at_goal_time"] is not None for e in part["episodes"])
    assert done >= 17, f"{path.stem}: {done} of 20 episodes done before max_steps"
