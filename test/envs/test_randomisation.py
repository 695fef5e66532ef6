"""Randomisation in training (vmas_ros/envs/randomisation.py, randomiser.py): what each setting draws, and
what it does to a step.

Each setting is checked against the engine without it, from the same seed
(randomisation draws after the scenario's reset, so the start states match).
"""
from __future__ import annotations

import math

import pytest
import torch

import vmas_ros
from vmas_ros.envs.environment import FEW_ACTION_ELEMENTS
from vmas_ros.envs.randomisation import SETTINGS, Randomisation

N_ENVS = 64
DT = 0.1  # navigation's


def _navigation(device, randomisation=None, n_envs: int = N_ENVS, **kwargs):
    return vmas_ros.make_env("navigation", num_envs=n_envs, device=device, seed=3, compile_physics=False,
                             randomisation=randomisation, **kwargs)


def test_settings_read_and_write_back_and_bad_ones_are_named():
    config = Randomisation.from_dict({"command_latency": [0.0, 0.2], "lidar_dropout": 0.1})
    assert config.command_latency == (0.0, 0.2) and config.lidar_dropout == (0.1, 0.1)
    assert Randomisation.from_dict(config.to_dict()) == config and config.active()
    assert not Randomisation().active() and set(config.to_dict()) == set(SETTINGS)
    for bad, message in [({"latency": 0.1}, r"unknown randomisation settings \['latency'\]"),
                         ({"actuator_lag": [0.2, 0.1]}, "actuator_lag must be finite with low <= high"),
                         ({"position_noise": -0.1}, "position_noise must be >= 0"),
                         ({"mass_scale": 0}, "mass_scale must be > 0"),
                         ({"lidar_dropout": [0.5, 1.5]}, "lidar_dropout is a probability"),
                         ({"drag_scale": "big"}, "drag_scale must be a number or"),
                         ({"velocity_noise": float("nan")}, "velocity_noise must be finite")]:
        with pytest.raises(ValueError, match=message):
            Randomisation.from_dict(bad)


def test_off_by_default_and_nothing_runs():
    env = _navigation("cpu", n_envs=2)
    assert env.randomiser is None


def test_each_setting_is_drawn_per_agent_and_env_within_its_range(device):
    ranges = {"command_latency": [0.0, 0.3], "actuator_lag": [0.05, 0.2], "position_noise": [0.0, 0.02],
              "velocity_noise": [0.01, 0.03], "lidar_noise": [0.0, 0.01], "lidar_dropout": [0.0, 0.2],
              "mass_scale": [0.8, 1.25], "drag_scale": [0.5, 1.5]}
    env = _navigation(device, ranges)
    for name, (low, high) in ranges.items():
        values = env.randomiser.params[name]
        assert values.shape == (env.n_agents, N_ENVS)
        assert bool((values >= low).all() and (values <= high).all()), name
        assert values.std() > (high - low) / 5, f"{name}: drawn across its range, not one value"
    # the latency in whole steps of dt, halves up: 0.3 s is 3 steps at most, and every step count occurs
    delays = env.randomiser._delay
    expected = torch.floor(env.randomiser.params["command_latency"] / DT + 0.5 + 1e-6).long()
    assert torch.equal(delays, expected) and set(delays.unique().tolist()) == {0, 1, 2, 3}
    assert Randomisation().latency_steps(0.15, DT) == 2 and Randomisation().latency_steps(0.149, DT) == 1
    before = env.randomiser.params["mass_scale"].clone()
    env.reset_at(torch.tensor([0, 5]))  # drawn anew for the envs reset only
    after = env.randomiser.params["mass_scale"]
    changed = (after != before).any(dim=0)
    assert changed[[0, 5]].all() and not changed[[1, 2, 3, 4]].any()


def _executed(env, commands):
    """The command agent 0 executes in env 0 for each of ``commands`` given in turn (same to all agents)."""
    executed = []
    for value in commands:
        env.step([torch.full((env.num_envs, 2), value, device=env.device)] * env.n_agents)
        executed.append(float(env.agents[0].action.u[0, 0]))
    return executed


def test_latency_delays_each_command_by_whole_steps_and_a_reset_starts_from_zero(device):
    env = _navigation(device, {"command_latency": 0.2}, n_envs=2)  # 2 steps
    assert _executed(env, [0.1, 0.2, 0.3, 0.4]) == pytest.approx([0.0, 0.0, 0.1, 0.2])
    env.reset_at(0)
    assert _executed(env, [0.5, 0.6, 0.7]) == pytest.approx([0.0, 0.0, 0.5])
    assert float(env.agents[0].action.u[1, 0]) == pytest.approx(0.5), "env 1 was not reset: still 2 steps late"


def test_lag_follows_the_command_with_its_time_constant(device):
    tau = 0.3
    env = _navigation(device, {"actuator_lag": tau}, n_envs=2)
    alpha = 1 - math.exp(-DT / tau)
    got = _executed(env, [1.0] * 4)
    assert got == pytest.approx([1 - (1 - alpha) ** k for k in range(1, 5)], rel=1e-5)


def test_position_noise_moves_every_position_derived_column_by_one_error(device):
    sigma = 0.05
    clean, noisy = _navigation(device), _navigation(device, {"position_noise": sigma})
    difference = torch.stack(noisy.reset()) - torch.stack(clean.reset())  # [A, B, obs]: the same start states
    own, to_goal = difference[..., 0:2], difference[..., 4:6]
    torch.testing.assert_close(own, to_goal)  # pos - goal carries the same error as pos
    assert 0.8 * sigma < float(own.std()) < 1.2 * sigma
    assert float(difference[..., 2:4].abs().max()) == 0 and float(difference[..., 6:].abs().max()) == 0


def test_lidar_noise_and_dropout_touch_only_rays_that_see_something(device):
    kwargs = dict(world_spawning_x=0.5, world_spawning_y=0.5)  # crowded: lidars see neighbours
    clean = torch.stack(_navigation(device, **kwargs).reset())[..., 6:]
    noisy = torch.stack(_navigation(device, {"lidar_noise": 0.02}, **kwargs).reset())[..., 6:]
    sees = clean > 0
    assert int(sees.sum()) > 50
    assert torch.equal(noisy[~sees], clean[~sees]), "a ray that sees nothing still sees nothing"
    assert 0.01 < float((noisy - clean)[sees & (clean > 0.05)].std()) < 0.03
    dropped = torch.stack(_navigation(device, {"lidar_dropout": 1.0}, **kwargs).reset())[..., 6:]
    assert float(dropped.abs().max()) == 0


def test_mass_and_drag_scales_act_in_the_engine_step(device):
    clean = _navigation(device, n_envs=4)
    scaled = _navigation(device, {"mass_scale": 2.0, "drag_scale": 0.0}, n_envs=4)
    push = [torch.full((4, 2), 0.5, device=device)] * clean.n_agents
    for env in (clean, scaled):
        env.step(push)
    # from rest: the first step's velocity is f / m dt, so twice the mass gives half of it
    for a, b in zip(clean.agents, scaled.agents):
        torch.testing.assert_close(b.state.vel, a.state.vel / 2)
    for env in (clean, scaled):
        env.step([torch.zeros_like(p) for p in push])
    # then coasting: drag takes (1 - 0.25) of the speed away in the clean world, nothing without drag
    for a, b in zip(clean.agents, scaled.agents):
        torch.testing.assert_close(b.state.vel, a.state.vel / 2 / 0.75, rtol=1e-4, atol=1e-6)


def test_settings_a_scenario_cannot_take_are_refused_naming_why():
    with pytest.raises(ValueError, match="balance's observations hold the agents' positions"):
        vmas_ros.make_env("balance", num_envs=2, randomisation={"position_noise": 0.01})
    with pytest.raises(ValueError, match="hold no lidar"):
        vmas_ros.make_env("navigation", num_envs=2, collisions=False, randomisation={"lidar_dropout": 0.1})
    with pytest.raises(ValueError, match="actuator_lag needs continuous actions"):
        vmas_ros.make_env("navigation", num_envs=2, continuous_actions=False, randomisation={"actuator_lag": 0.1})


def test_a_compiled_step_reads_the_scales_drawn_at_each_reset():
    """The compiled step keeps reading the constants it was compiled with: new draws must land in them. The
    observation noise, drawn from the same stream, gives the same numbers."""
    settings = {"mass_scale": [0.5, 2.0], "drag_scale": [0.5, 1.5], "command_latency": [0.0, 0.2],
                "actuator_lag": [0.0, 0.2], "position_noise": 0.01, "lidar_noise": 0.01, "lidar_dropout": 0.2}
    eager, compiled = (vmas_ros.make_env("navigation", num_envs=4, n_agents=2, seed=1, compile_physics=flag,
                                         randomisation=settings) for flag in (False, True))
    generator = torch.Generator().manual_seed(0)
    for step in range(12):
        actions = torch.rand(2, 4, 2, generator=generator) * 2 - 1
        results = [env.step(actions.clone())[0] for env in (eager, compiled)]
        torch.testing.assert_close(results[1], results[0], atol=1e-5, rtol=1e-5)
        if step == 4:
            for env in (eager, compiled):
                env.reset_at(torch.tensor([1, 2]))
    assert compiled.world.physics_compiled and compiled.world.tables.scales is not None


def test_a_layout_wider_than_the_observations_is_refused_naming_both():
    from vmas_ros.scenarios.navigation import Scenario
    from vmas_ros.simulator.observation_layout import ObservationLayout

    class _WideLayout(Scenario):
        def observation_layout(self, agent):
            return ObservationLayout(position=((40, 1),))

    with pytest.raises(ValueError, match="the observation layout needs 42 columns, but the observations have 18"):
        vmas_ros.make_env(_WideLayout(), num_envs=2, compile_physics=False, randomisation={"position_noise": 0.01})


def test_each_observation_element_reads_its_errors_number_from_the_seed_step_and_element(device):
    """The noise's numbering, from sensor_noise's parts by hand: per agent and env, numbers 0-1 are the
    position's error, 2-3 the velocity's and one per lidar ray after them; every column that moves with the
    position (the position and the position minus the goal) takes the same one."""
    from vmas_ros.envs import sensor_noise
    from vmas_ros.envs.randomiser import SEED_OFFSET

    sigmas = {"position_noise": 0.05, "velocity_noise": 0.03, "lidar_noise": 0.02, "lidar_dropout": 0.3}
    kwargs = dict(n_envs=16, world_spawning_x=0.5, world_spawning_y=0.5)  # crowded: lidars see neighbours
    clean_env, noisy_env = _navigation(device, **kwargs), _navigation(device, sigmas, **kwargs)
    for env in (clean_env, noisy_env):
        env.seed(3)  # the noise's steps count from here: the reset's observations are its step 0
    clean, noisy = torch.stack(clean_env.reset()), torch.stack(noisy_env.reset())  # [A, B, 18]
    n_agents, n_envs, _ = clean.shape
    rays = noisy_env.scenario.n_lidar_rays
    int32 = lambda value: torch.tensor(value, dtype=torch.int32, device=device)
    key = sensor_noise.stream_key(sensor_noise.hash32(int32(SEED_OFFSET + 3)), int32(0))  # the first noise step
    numbers = sensor_noise.hashes(key, (n_agents, n_envs, 4 + rays))
    errors = sensor_noise.normals(numbers, torch.float32)
    expected = clean.clone()
    expected[..., 0:2] += errors[..., 0:2] * sigmas["position_noise"]
    expected[..., 2:4] += errors[..., 2:4] * sigmas["velocity_noise"]
    expected[..., 4:6] += errors[..., 0:2] * sigmas["position_noise"]
    readings = clean[..., 6:]
    kept = (readings != 0) & (sensor_noise.uniforms(numbers[..., 4:], torch.float32) > sigmas["lidar_dropout"])
    seen = (readings + errors[..., 4:] * sigmas["lidar_noise"]).clamp(0.0, noisy_env.scenario.lidar_range)
    expected[..., 6:] = torch.where(kept, seen, torch.zeros_like(readings))
    assert int(kept.sum()) > 0 and int(((readings != 0) & ~kept).sum()) > 0, "some rays seen, some dropped"
    assert torch.equal(noisy, expected)


def test_a_layout_that_moves_a_column_with_two_errors_is_refused_naming_it():
    from vmas_ros.scenarios.navigation import Scenario
    from vmas_ros.simulator.observation_layout import ObservationLayout

    class _Overlapping(Scenario):
        def observation_layout(self, agent):
            return ObservationLayout(position=((0, 1),), velocity=((1, 1),))

    with pytest.raises(ValueError, match="observation column 1 moves with both the position and the velocity"):
        vmas_ros.make_env(_Overlapping(), num_envs=2, compile_physics=False, randomisation={"position_noise": 0.01})


@pytest.mark.parametrize("compiled", [False, True], ids=["eager", "compiled"])
@pytest.mark.parametrize("bad", [2.0, float("nan")], ids=["out_of_range", "nan"])
def test_a_bad_command_is_refused_naming_its_agent_and_nothing_of_it_is_executed(bad, compiled):
    """Enough envs that the randomiser's own pass checks the commands: a refused step leaves the history,
    the lag and the forces as they were, so the run goes on as if it had never been asked."""
    settings = {"command_latency": 0.1, "actuator_lag": 0.2}
    n_envs = FEW_ACTION_ELEMENTS  # 2 agents x 2 components each: four times the elements checked by clamping
    twins = [vmas_ros.make_env("navigation", num_envs=n_envs, n_agents=2, seed=1, compile_physics=compiled,
                               randomisation=settings) for _ in range(2)]
    commands = [[torch.full((n_envs, 2), value) for _ in range(2)] for value in (0.5, -0.3, 0.8)]
    refused, clean = twins
    refused.step(commands[0])
    clean.step(commands[0])
    forces_before = refused.agents[1].state.force.clone()
    wrong = [commands[1][0], commands[1][1].clone()]
    wrong[1][7, 1] = bad
    with pytest.raises(ValueError, match=refused.agents[1].name):
        refused.step(wrong)
    assert torch.equal(refused.agents[1].state.force, forces_before), "the refused commands reached the forces"
    for step in commands[1:]:
        for env in twins:
            env.step(step)
        torch.testing.assert_close(refused.agents[0].action.u, clean.agents[0].action.u, rtol=0, atol=0)
        torch.testing.assert_close(refused.agents[1].state.pos, clean.agents[1].state.pos, rtol=0, atol=0)
