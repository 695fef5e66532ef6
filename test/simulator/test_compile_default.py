"""The default mode: make_env steps eagerly, then compiles at a step the workload sets, where a compiler works.

The rest of the suite runs eager (VMAS_ROS_COMPILE=0, test/conftest.py); these
tests set the variable themselves.
"""
from __future__ import annotations

import logging
import os
import subprocess
import sys
import textwrap

import pytest
import torch

import vmas_ros
from vmas_ros.simulator import compile_default


@pytest.fixture
def fresh_notes(monkeypatch):
    """Forget the process's one-line notes and the compiler probe, so each test sees its own."""
    monkeypatch.setattr(compile_default, "_said", set())
    compile_default._cpu_compiler_missing.cache_clear()
    yield
    compile_default._cpu_compiler_missing.cache_clear()


@pytest.mark.parametrize("value, expected", [("auto", None), ("AUTO", None), ("", None), ("1", True), ("0", False)])
def test_the_environment_variable_sets_the_default(monkeypatch, value, expected):
    monkeypatch.setenv(compile_default.ENV_VAR, value)
    assert compile_default.MODES[compile_default.env_mode()] is expected


def test_a_bad_setting_is_refused_naming_it(monkeypatch):
    monkeypatch.setenv(compile_default.ENV_VAR, "yes")
    with pytest.raises(ValueError, match=r"VMAS_ROS_COMPILE='yes': expected one of auto, 1, 0"):
        vmas_ros.make_env("simple_spread", num_envs=2)
    monkeypatch.setenv(compile_default.ENV_VAR, "0")
    with pytest.raises(TypeError, match=r"compile_physics must be True, False or None .* got 'yes'"):
        vmas_ros.make_env("simple_spread", num_envs=2, compile_physics="yes")


def test_the_default_plans_its_switch_from_the_workload_up_to_a_size(monkeypatch, device):
    monkeypatch.setenv(compile_default.ENV_VAR, "auto")
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_MAX_ENVS", 4)
    env = vmas_ros.make_env("simple_spread", num_envs=4, device=device)
    entities = len(env.world.entities)
    assert entities == 6 and not env.world.physics_compiled
    assert env.world.compiled_from_step == compile_default.default_switch_step(4, entities)
    assert vmas_ros.make_env("simple_spread", num_envs=5, device=device).world.compiled_from_step is None
    # an explicit choice wins over the default and the variable
    assert vmas_ros.make_env("simple_spread", num_envs=4, device=device,
                             compile_physics=False).world.compiled_from_step is None
    monkeypatch.setenv(compile_default.ENV_VAR, "1")
    assert vmas_ros.make_env("simple_spread", num_envs=5, device=device).world.compiled_from_step == 0
    monkeypatch.setenv(compile_default.ENV_VAR, "0")
    assert vmas_ros.make_env("simple_spread", num_envs=4, device=device, compile_physics=True).world.physics_compiled


def test_the_switch_step_follows_the_work_and_not_the_clock(monkeypatch):
    work, floor = compile_default.DEFAULT_COMPILE_AFTER_WORK, compile_default.DEFAULT_COMPILE_MIN_STEP_WORK
    assert compile_default.default_switch_step(1000, 6) == -(-work // 6000)
    assert compile_default.default_switch_step(32, 6) == compile_default.default_switch_step(1, 1) == -(-work // floor)
    # the sizes people time as short runs stay eager past 10,000 steps; thousands of envs switch early
    assert compile_default.default_switch_step(32, 6) > 10_000  # transport, 32 envs
    assert compile_default.default_switch_step(60, 8) > 10_000  # navigation, TorchRL's tutorial size
    assert compile_default.default_switch_step(10_000, 6) <= 100
    assert compile_default.default_switch_step(10 ** 9, 10) == 1  # at least one eager step
    assert compile_default.default_switch_step(1, 6) < 20_000  # one env compiles too, as the fixed cost counts
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_AFTER_WORK", 100)
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_MIN_STEP_WORK", 1)
    assert compile_default.default_switch_step(4, 6) == 5


@pytest.mark.parametrize("bad", [-1, 1.5, True, "3"])
def test_a_bad_switch_step_is_refused_naming_it(bad):
    world = vmas_ros.make_env("simple_spread", num_envs=2, compile_physics=False).world
    with pytest.raises(ValueError, match=r"after_steps must be a whole number of steps >= 0, got " + repr(bad)):
        world.compile_physics(after_steps=bad)
    with pytest.raises(ValueError, match=r"after_steps=3 needs enabled=True and background=False"):
        world.compile_physics(background=True, after_steps=3)


_NO_COMPILER_SCRIPT = textwrap.dedent("""
    import sys, torch, vmas_ros
    env = vmas_ros.make_env(sys.argv[1], num_envs=int(sys.argv[2]), seed=0)
    assert env.world.compiled_from_step > int(sys.argv[3]), env.world.compiled_from_step
    for _ in range(int(sys.argv[3])):
        env.step([env.get_random_action(agent) for agent in env.agents])
    loaded = sorted(m for m in sys.modules if m.startswith(("torch._dynamo", "torch._inductor")))
    assert not loaded, loaded
    print("EAGER_OK")
""")


def test_a_short_run_never_loads_the_compiler():
    """A short script in the default mode: its steps are eager, and torch's compiler is never imported
    (it would add its memory and import time to every short script)."""
    env = dict(os.environ, VMAS_ROS_COMPILE="auto")
    done = subprocess.run([sys.executable, "-c", _NO_COMPILER_SCRIPT, "transport", "32", "100"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0 and "EAGER_OK" in done.stdout, done.stderr[-3000:]


def test_without_a_compiler_the_default_is_eager_and_says_so_once(monkeypatch, caplog, fresh_notes):
    from torch._inductor import config

    monkeypatch.setenv(compile_default.ENV_VAR, "auto")
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_AFTER_WORK", 1)  # the switch is due at once
    with config.patch({"cpp.cxx": ("/nonexistent/c++",)}), caplog.at_level(logging.WARNING, logger="vmas_ros"):
        envs = [vmas_ros.make_env("simple_spread", num_envs=2, device="cpu") for _ in range(2)]
        for env in envs:
            for _ in range(3):
                env.step([torch.zeros(2, 2) for _ in env.agents])  # the switch comes, and it steps on
    assert not any(env.world.physics_compiled for env in envs)
    assert all(env.world.compiled_from_step is None for env in envs)
    notes = [r.getMessage() for r in caplog.records if r.name == "vmas_ros"]
    assert len(notes) == 1 and notes[0].startswith("vmas_ros: physics runs eagerly (slower): no working C++ compiler")


#: a compiler that answers --version but cannot compile (a broken toolchain); stepping must fall back
_BROKEN_COMPILER = "#!/bin/sh\nif [ \"$1\" = --version ]; then echo broken-c++ 1.0; exit 0; fi\nexit 1\n"

_FALLBACK_SCRIPT = textwrap.dedent("""
    import logging, sys, torch
    logging.basicConfig(level=logging.WARNING, format="%(name)s|%(message)s")
    import vmas_ros
    def roll(env):
        gen = torch.Generator().manual_seed(0)
        out = []
        for _ in range(3):
            env.step([torch.rand(4, 2, generator=gen) * 2 - 1 for _ in env.agents])
            out.append(env.world.stacked_state("pos").clone())
        return torch.stack(out)
    expected = roll(vmas_ros.make_env("simple_spread", num_envs=4, seed=1, compile_physics=False))
    if sys.argv[1] == "first-step":  # compile_physics=True: the compile fails inside the first step
        fallen = vmas_ros.make_env("simple_spread", num_envs=4, seed=1, compile_physics=True)
        assert fallen.world.physics_compiled
        got = roll(fallen)
        assert not fallen.world.physics_compiled, "a failed compile must leave the world eager"
    else:  # sim_node's default: the compile fails on its thread while the world steps eagerly
        fallen = vmas_ros.make_env("simple_spread", num_envs=4, seed=1, compile_physics=False)
        fallen.world.compile_physics(background=True)
        got = roll(fallen)
        compiler = fallen.world.background_compiler
        assert compiler.wait(timeout=300) and compiler.failed >= 1 and compiler.compiled == 0, vars(compiler)
        roll(fallen)  # and it goes on stepping
    assert torch.equal(got, expected), "the steps must be the eager steps, bit for bit"
    print("FALLBACK_OK")
""")


@pytest.mark.slow
@pytest.mark.parametrize("where", ["first-step", "background"])
def test_a_compiler_that_fails_leaves_the_steps_eager(tmp_path, where):
    """A compiler that cannot compile: the compile fails inside the first step or on its thread
    (background), and every step runs eagerly, with one log line; no step is lost."""
    compiler = tmp_path / "broken-c++"
    compiler.write_text(_BROKEN_COMPILER)
    compiler.chmod(0o755)
    # CXX: the compiler torch.compile uses, in every thread (inductor's config is per thread)
    env = dict(os.environ, VMAS_ROS_COMPILE="auto", CXX=str(compiler), TORCHINDUCTOR_CACHE_DIR=str(tmp_path / "inductor"))
    done = subprocess.run([sys.executable, "-c", _FALLBACK_SCRIPT, where], capture_output=True,
                          text=True, env=env, timeout=300)
    assert done.returncode == 0 and "FALLBACK_OK" in done.stdout, done.stderr[-3000:]
    notes = [line for line in done.stderr.splitlines() if line.startswith("vmas_ros|")]
    assert len(notes) == 1 and "compiling the physics step failed (" in notes[0] and notes[0].endswith(
        "it runs eagerly"), done.stderr[-3000:]


@pytest.mark.slow
def test_seeded_default_runs_repeat_bit_for_bit_across_the_switch(monkeypatch, fresh_notes):
    """The default mode's switch, brought forward to step 8: two seeded runs give the same trajectory bit
    for bit, eager up to the switch (the eager step's own bits) and compiled after it."""
    monkeypatch.setenv(compile_default.ENV_VAR, "auto")
    if compile_default.compiler_missing("cpu"):
        pytest.fail(f"the test machine needs a C++ compiler: {compile_default.compiler_missing('cpu')}")
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_AFTER_WORK", 8 * 8 * 6)  # 8 envs, 6 entities: step 8
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_MIN_STEP_WORK", 1)

    def run(**kwargs):
        env = vmas_ros.make_env("transport", num_envs=8, seed=7, **kwargs)
        gen = torch.Generator().manual_seed(3)
        states, compiled = [], []
        for _ in range(20):
            obs, rews, _, _ = env.step([torch.rand(8, 2, generator=gen) * 2 - 1 for _ in env.agents])
            compiled.append(env.world.physics_compiled)
            states.append(torch.cat([env.world.stacked_state("pos").flatten(), torch.cat(obs, -1).flatten(),
                                     torch.cat(rews).flatten()]))
        return torch.stack(states), compiled

    first, compiled = run()
    assert compiled == [False] * 8 + [True] * 12
    second, _ = run()
    assert torch.equal(first, second)
    eager, _ = run(compile_physics=False)
    assert torch.equal(first[:8], eager[:8])
    assert torch.allclose(first, eager, atol=1e-4)  # compiled: the eager step to float rounding
    assert (first[-1] - first[0]).abs().max() > 1e-3  # the agents moved
