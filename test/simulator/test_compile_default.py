"""The default mode: make_env compiles the physics where a compiler works, and falls back to eager where not.

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


def test_the_default_compiles_where_a_compiler_works_up_to_a_size(monkeypatch, device, fresh_notes):
    monkeypatch.setenv(compile_default.ENV_VAR, "auto")
    monkeypatch.setattr(compile_default, "DEFAULT_COMPILE_MAX_ENVS", 4)
    works = compile_default.compiler_missing(device) is None
    assert vmas_ros.make_env("simple_spread", num_envs=4, device=device).world.physics_compiled == works
    assert not vmas_ros.make_env("simple_spread", num_envs=5, device=device).world.physics_compiled
    # an explicit choice wins over the default and the variable
    assert not vmas_ros.make_env("simple_spread", num_envs=4, device=device, compile_physics=False).world.physics_compiled
    monkeypatch.setenv(compile_default.ENV_VAR, "1")
    assert vmas_ros.make_env("simple_spread", num_envs=5, device=device).world.physics_compiled
    monkeypatch.setenv(compile_default.ENV_VAR, "0")
    assert vmas_ros.make_env("simple_spread", num_envs=4, device=device, compile_physics=True).world.physics_compiled


def test_without_a_compiler_the_default_is_eager_and_says_so_once(monkeypatch, caplog, fresh_notes):
    from torch._inductor import config

    monkeypatch.setenv(compile_default.ENV_VAR, "auto")
    with config.patch({"cpp.cxx": ("/nonexistent/c++",)}), caplog.at_level(logging.WARNING, logger="vmas_ros"):
        envs = [vmas_ros.make_env("simple_spread", num_envs=2, device="cpu") for _ in range(2)]
    assert not any(env.world.physics_compiled for env in envs)
    notes = [r.getMessage() for r in caplog.records if r.name == "vmas_ros"]
    assert len(notes) == 1 and notes[0].startswith("vmas_ros: physics runs eagerly (slower): no working C++ compiler")
    envs[0].step([torch.zeros(2, 2) for _ in envs[0].agents])  # and it steps


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
    if sys.argv[1] == "first-step":  # make_env's default: the compile fails inside the first step
        fallen = vmas_ros.make_env("simple_spread", num_envs=4, seed=1)
        assert fallen.world.physics_compiled, "the default should have tried to compile"
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
    """A compiler that cannot compile: the compile fails inside the first step (make_env) or on its thread
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
def test_seeded_default_runs_are_reproducible(monkeypatch, fresh_notes):
    """Two seeded envs of the default mode (compiled here) give the same trajectory bit for bit:
    make_env builds the compiled step on the first step, before any state depends on it."""
    monkeypatch.setenv(compile_default.ENV_VAR, "auto")
    if compile_default.compiler_missing("cpu"):
        pytest.fail(f"the test machine needs a C++ compiler: {compile_default.compiler_missing('cpu')}")
    runs = []
    for _ in range(2):
        env = vmas_ros.make_env("transport", num_envs=8, seed=7)
        assert env.world.physics_compiled
        gen = torch.Generator().manual_seed(3)
        states = []
        for _ in range(20):
            obs, rews, _, _ = env.step([torch.rand(8, 2, generator=gen) * 2 - 1 for _ in env.agents])
            states.append(torch.cat([env.world.stacked_state("pos").flatten(), torch.cat(obs, -1).flatten(),
                                     torch.cat(rews).flatten()]))
        runs.append(torch.stack(states))
    assert torch.equal(runs[0], runs[1])
    assert (runs[0][-1] - runs[0][0]).abs().max() > 1e-3  # the agents moved
