"""The training recipes under config/: each is a valid TrainConfig whose envs build, randomise and step, with
ranges that cover robot_fleet's conditions (docs/fleet.md)."""
from pathlib import Path

import pytest
import torch

import vmas_ros
from vmas_ros.train.config import TrainConfig, load_config_file

RECIPES = sorted((Path(__file__).resolve().parents[2] / "config" / "train").glob("*.yaml"))
#: robot_fleet's defaults in deploy-eval: 50 ms latency, 0.1 s lag, odometry noise 0.01 m and 0.02 m/s
FLEET = {"command_latency": 0.05, "actuator_lag": 0.1, "position_noise": 0.01, "velocity_noise": 0.02}


def test_the_three_recipes_are_there():
    assert [path.stem for path in RECIPES] == ["navigation_diff_drive", "navigation_holonomic",
                                               "simple_spread"]


@pytest.mark.parametrize("path", RECIPES, ids=lambda path: path.stem)
def test_a_recipe_trains_envs_that_step_with_its_randomisation(path):
    config = TrainConfig.from_dict(load_config_file(path), source=str(path))
    for name, value in FLEET.items():
        low, high = config.randomisation[name]
        assert low <= value <= high, f"{path.name}: {name} {[low, high]} does not cover the fleet's {value}"
    env = vmas_ros.make_env(config.scenario, num_envs=4, seed=0, compile_physics=False,
                            randomisation=config.randomisation, **config.scenario_kwargs)
    assert env.randomiser is not None
    observations, rewards, dones, _ = env.step(torch.zeros(env.n_agents, 4, env.get_agent_action_size(env.agents[0])))
    assert observations.shape[:2] == (env.n_agents, 4) and bool(torch.isfinite(observations).all())
