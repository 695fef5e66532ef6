"""gymnasium's registry and VMAS's wrappers, both at once (vmas_ros/envs/gymnasium_registry.py).

Registered ids (``vmas_ros/<scenario>-v0``) are gymnasium-native and pass
gymnasium's own checker on ``env.unwrapped``; a user's own registration of
``make_env(..., wrapper="gymnasium")`` (VMAS's convention: ``env.unwrapped`` is
the Environment) works with ``gymnasium.make`` and ``make_vec`` too.
"""
from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import vmas_ros
from vmas_ros.envs.environment import Environment
from vmas_ros.compat.gymnasium_ids import env_id, register_envs

SCENARIOS = vmas_ros.list_scenarios()
RENDERED = ("navigation", "transport", "simple_spread")


def _checked(env) -> None:
    """gymnasium's checker on ``env``; its warnings are failures, but for unbounded observation boxes
    (VMAS's observations are unbounded)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=env.render_mode is None)
    complaints = [str(w.message) for w in caught if "infinity" not in str(w.message)]
    assert not complaints, complaints


@pytest.mark.parametrize("first", ["vmas_ros", "gymnasium"])
def test_import_vmas_ros_does_not_import_gymnasium_and_the_ids_register_in_either_order(first):
    second = "gymnasium" if first == "vmas_ros" else "vmas_ros"
    code = (f"import sys; import {first}; light = 'gymnasium' not in sys.modules; import {second}; "
            "import gymnasium; print(light, 'vmas_ros/navigation-v0' in gymnasium.registry)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    light, registered = done.stdout.split()
    assert registered == "True"
    assert light == ("True" if first == "vmas_ros" else "False")


def test_every_scenario_has_an_id():
    ids = register_envs()
    # every scenario registered now, those a test may have added to the registry included
    assert ids == [env_id(name) for name in vmas_ros.list_scenarios()] and all(name in gymnasium.registry for name in ids)
    assert {env_id(name) for name in SCENARIOS} <= set(ids)
    assert register_envs() == ids, "registering again changes nothing"


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_every_id_makes_a_native_env_that_passes_gymnasiums_checker(scenario):
    render_mode = "rgb_array" if scenario in RENDERED else None
    env = gymnasium.make(env_id(scenario), max_steps=20, seed=0, render_mode=render_mode)
    assert env.unwrapped is env.unwrapped.unwrapped and isinstance(env.unwrapped, gymnasium.Env)
    assert env.spec.id == env_id(scenario) and isinstance(env.unwrapped.env, Environment)
    _checked(env.unwrapped)
    observation, _ = env.reset(seed=1)
    assert isinstance(observation, tuple) and observation in env.observation_space
    _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
    assert isinstance(reward, float) and isinstance(terminated, bool) and isinstance(truncated, bool)
    vector = gymnasium.make_vec(env_id(scenario), num_envs=3, vectorization_mode="vector_entry_point", max_steps=20)
    assert vector.num_envs == 3 and vector.spec.id == env_id(scenario)
    observations, _ = vector.reset(seed=0)
    assert observations in vector.observation_space
    _, rewards, terminated, truncated, _ = vector.step(vector.action_space.sample())
    assert rewards.shape == (3,) and terminated.shape == truncated.shape == (3,)


def test_make_vec_takes_gymnasiums_max_episode_steps():
    vector = gymnasium.make_vec(env_id("navigation"), num_envs=4, vectorization_mode="vector_entry_point",
                                max_episode_steps=2)
    vector.reset(seed=0)
    for _ in range(2):
        _, _, _, truncated, _ = vector.step(vector.action_space.sample())
    assert truncated.all()


def _vmas_style(**kwargs):
    return vmas_ros.make_env("navigation", num_envs=1, wrapper="gymnasium", **kwargs)


def _vmas_style_vector(num_envs=2, **kwargs):
    return vmas_ros.make_env("navigation", num_envs=num_envs, wrapper="gymnasium_vec", **kwargs)


def test_a_users_own_registration_of_the_vmas_wrappers_works_with_make_and_make_vec():
    gymnasium.register(id="user/vmas-style-v0", entry_point=_vmas_style, vector_entry_point=_vmas_style_vector)
    try:
        env = gymnasium.make("user/vmas-style-v0", max_steps=10)
        assert env.spec.id == "user/vmas-style-v0"
        assert isinstance(env.unwrapped, Environment), "VMAS code keeps reading the Environment"
        observation, _ = env.reset(seed=0)
        assert len(observation) == env.unwrapped.n_agents
        env.step([np.zeros(2, dtype=np.float32) for _ in range(env.unwrapped.n_agents)])
        vector = gymnasium.make_vec("user/vmas-style-v0", num_envs=3, vectorization_mode="vector_entry_point")
        assert vector.spec.id == "user/vmas-style-v0" and vector.num_envs == 3
        assert isinstance(vector.unwrapped, Environment)
        vector.reset(seed=0)
    finally:
        del gymnasium.registry["user/vmas-style-v0"]
