"""Compiling on a thread of its own (World.compile_physics(background=True), sim_node's default).

The world steps eagerly, never waiting, until its compiled functions are
ready, then runs them compiled from its next step on, all at once. These tests
pin what the switch may and may not change: nothing before it, float rounding
after it, and the same trajectory for the same switch step, whether the
switch came from the background compile or was planned (the default mode's).
"""
from __future__ import annotations

import pytest
import torch

import vmas_ros
from vmas_ros.simulator.background_compile import BackgroundCompiler, copy_inputs
from vmas_ros.simulator.physics.types import PlanarState

STEPS_BEFORE, STEPS_AFTER, NUM_ENVS = 4, 12, 8


def _actions(env, steps: int, seed: int = 3):
    gen = torch.Generator().manual_seed(seed)
    return [[torch.rand(NUM_ENVS, env.get_agent_action_size(a), generator=gen) * 2 - 1 for a in env.agents]
            for _ in range(steps)]


def _state(env) -> torch.Tensor:
    return torch.cat([env.world.stacked_state(f).flatten() for f in ("pos", "vel", "rot", "ang_vel")])


def _run(actions, background: bool, switch_at: int, planned: bool = False):
    """transport (sphere and box contacts), stepped with ``actions``; with ``background`` its compile is
    waited for after ``switch_at`` steps, so that the compiled step takes over from the next one; with
    ``planned``, the switch is planned at that step (``compile_physics(after_steps=...)``)."""
    env = vmas_ros.make_env("transport", num_envs=NUM_ENVS, seed=7, compile_physics=False)
    if background:
        env.world.compile_physics(background=True)
    if planned:
        env.world.compile_physics(after_steps=switch_at)
    states, observations = [], []
    for index, step_actions in enumerate(actions):
        if background and index == switch_at:
            assert env.world.background_compiler.wait(timeout=600), "the background compile did not finish"
        obs, rews, _, _ = env.step(step_actions)
        states.append(_state(env))
        observations.append(torch.cat([torch.cat(obs, -1).flatten(), torch.cat(rews)]))
    return env, torch.stack(states), torch.stack(observations)


@pytest.mark.slow
def test_the_switch_changes_nothing_before_it_and_only_rounding_after_and_is_repeatable():
    probe = vmas_ros.make_env("transport", num_envs=NUM_ENVS, seed=7, compile_physics=False)
    actions = _actions(probe, STEPS_BEFORE + STEPS_AFTER)
    _, eager_states, eager_obs = _run(actions, background=False, switch_at=0)
    from vmas_ros.simulator.direct_graph import graphs_compiled

    graphs = graphs_compiled()
    env, states, obs = _run(actions, background=True, switch_at=STEPS_BEFORE)
    compiler = env.world.background_compiler
    assert compiler.idle and compiler.compiled >= 1 and compiler.failed == 0 and compiler.first_ready_s > 0
    assert graphs_compiled() > graphs  # compiled code was made (and is what ran after the switch)
    copies = list(env.world._compiled.step._copies.values())
    assert copies and not any(copy._eager_until_compiled for copy in copies) and all(c.one_graph for c in copies)
    assert compiler.released and env.world.compiled_from_step == STEPS_BEFORE
    # until the switch the world ran its eager functions: the eager world's steps, bit for bit
    assert torch.equal(states[:STEPS_BEFORE], eager_states[:STEPS_BEFORE])
    assert torch.equal(obs[:STEPS_BEFORE], eager_obs[:STEPS_BEFORE])
    # after it, the compiled step: equal to float rounding over this short horizon
    torch.testing.assert_close(states, eager_states, atol=1e-5, rtol=1e-4)
    # (transport's rewards are differences of distances: one rounding of a distance is the whole reward's)
    torch.testing.assert_close(obs, eager_obs, atol=1e-4, rtol=1e-4)
    assert (eager_states[-1] - eager_states[0]).abs().max() > 1e-3  # the world moved
    # a seeded run that switches at the same step agrees bit for bit, also when the switch is planned (the
    # default mode's, and how a node's logged switch step is repeated offline): the switch adds no state
    planned, again, again_obs = _run(actions, background=False, switch_at=STEPS_BEFORE, planned=True)
    assert planned.world.compiled_from_step == STEPS_BEFORE and planned.world.physics_compiled
    assert torch.equal(again, states) and torch.equal(again_obs, obs)


def test_inputs_are_copied_and_tables_are_shared():
    q, v = torch.zeros(3, 2, 4), torch.ones(3, 2, 4)
    tables = object()
    state, got_tables, actions = copy_inputs((PlanarState(q, v), tables, [torch.ones(2)]))
    assert state.q is not q and torch.equal(state.q, q) and state.v is not v
    assert got_tables is tables and actions[0] is not None


def test_a_failed_job_leaves_the_function_eager_and_the_compiler_idle():
    compiler = BackgroundCompiler()
    outcomes = []

    def compile_now(x):
        raise RuntimeError(f"cannot compile {x.shape}")

    compiler.submit(compile_now, (torch.zeros(2),), {}, outcomes.append)
    assert compiler.wait(timeout=60)
    assert outcomes == [False] and (compiler.compiled, compiler.failed) == (0, 1) and compiler.first_ready_s >= 0
