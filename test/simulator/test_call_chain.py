"""The path of one ``env.step`` down to the integrator stays short and runs one way (docs/engine.md).

Traced with ``sys.setprofile``: the package's frames on the stack when the
integrator runs (eager), or when the compiled step is entered (compiled; the
rest of its path is the eager path from ``pipeline.advance`` down, which the
compiler traced, and the compiled code is called straight from
``compiling.py``). At most 6 package files may be on that chain, and no file
may come back after another one was entered below it (no A -> B -> A).
"""
from __future__ import annotations

import os
import sys
from typing import List, Tuple

import pytest

import vmas_ros
from vmas_ros.simulator.physics import integrator

ROOT = os.path.dirname(vmas_ros.__file__)
MAX_FILES = 6
Chain = List[Tuple[str, str]]  # (file relative to the package, function), outermost first


def _package_frames(frame) -> Chain:
    chain = []
    while frame is not None:
        if frame.f_code.co_filename.startswith(ROOT):
            chain.append((os.path.relpath(frame.f_code.co_filename, ROOT), frame.f_code.co_name))
        frame = frame.f_back
    return chain[::-1]


def _from_env_step(chain: Chain) -> Chain:
    starts = [i for i, (path, name) in enumerate(chain) if (path, name) == ("envs/environment.py", "step")]
    assert starts, f"Environment.step is not on the chain: {chain}"
    return chain[starts[-1]:]


def _step_profiled(env, on_call) -> None:
    """One random step of ``env`` with ``on_call(frame)`` called for every Python function call."""
    def profile(frame, event, arg):
        if event == "call":
            on_call(frame)

    actions = env.get_random_actions()
    sys.setprofile(profile)
    try:
        env.step(actions)
    finally:
        sys.setprofile(None)


def _eager_chain(env) -> Chain:
    seen: List[Chain] = []
    _step_profiled(env, lambda frame: frame.f_code is integrator.integrate.__code__
                   and seen.append(_package_frames(frame)))
    assert seen, "the integrator never ran"
    return _from_env_step(seen[0])


def _compiled_entry(env) -> Chain:
    """The package frames under which the compiled step runs (torch's code, or inductor's generated code,
    called from the direct call)."""
    from torch._inductor.runtime.cache_dir_utils import cache_dir

    generated = cache_dir()
    seen: List[Chain] = []

    def on_call(frame):
        filename = frame.f_code.co_filename
        if f"{os.sep}torch{os.sep}" in filename or filename.startswith(generated):
            chain = _package_frames(frame)
            if chain and chain[-1] == ("simulator/compiling.py", "_compiled_call"):
                seen.append(chain)

    _step_profiled(env, on_call)
    assert seen, "no compiled step was entered"
    return _from_env_step(max(seen, key=len))


def _files(chain: Chain) -> List[str]:
    """The chain's files in order, each run of frames in one file counted once."""
    files: List[str] = []
    for path, _ in chain:
        if not files or files[-1] != path:
            files.append(path)
    return files


def _check(chain: Chain) -> None:
    files = _files(chain)
    assert len(set(files)) <= MAX_FILES, f"{len(set(files))} files on the step's path: {files}"
    assert len(files) == len(set(files)), f"the path goes back into a file above it: {files}"


def test_eager_step_reaches_the_integrator_through_few_files():
    env = vmas_ros.make_env("transport", num_envs=4, seed=0)
    chain = _eager_chain(env)
    _check(chain)
    assert _files(chain) == ["envs/environment.py", "simulator/world.py", "simulator/physics/pipeline.py",
                             "simulator/physics/integrator.py"]


@pytest.mark.slow
def test_compiled_step_reaches_the_integrator_through_few_files():
    env = vmas_ros.make_env("simple_spread", num_envs=2, seed=0, compile_physics=True)
    for _ in range(2):  # compiles
        env.step(env.get_random_actions())
    entry = _compiled_entry(env)
    eager = _eager_chain(vmas_ros.make_env("simple_spread", num_envs=2, seed=0))
    inside = eager[[name for _, name in eager].index("advance"):]  # what the compiler traced, from advance
    chain = entry + inside
    _check(chain)
    assert "simulator/compiling.py" in _files(chain)


def test_the_check_catches_a_path_that_comes_back():
    with pytest.raises(AssertionError, match="goes back"):
        _check([("a.py", "f"), ("b.py", "g"), ("a.py", "h")])
    with pytest.raises(AssertionError, match="files on the step's path"):
        _check([(f"{i}.py", "f") for i in range(MAX_FILES + 1)])
