"""World size limits: count kwargs must be counts, and absurd worlds are refused before anything is built.

Without the limits ``n_agents=10**9`` makes ``make_world`` allocate until the
machine gives up. The refusal must come at once, name the value and the
limit, and say how to opt in; the sizes this project runs (30,000 envs x 100
agents) must stay allowed. The huge case runs in a child process with a memory
cap and a timeout, so a missing limit fails the test instead of the machine.
"""
from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import vmas_ros
from vmas_ros.envs.limits import ALLOW_ENV, MAX_COUNT, MAX_WORLD, check_world_size

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("value, shown", [
    (1e9, "1000000000.0 (float)"), (4.0, "4.0 (float)"), ("4", "'4' (str)"), (True, "True (bool)"),
    (None, "None (NoneType)"), (-1, "-1"),
])
def test_a_count_kwarg_must_be_an_int_at_least_0(value, shown):
    with pytest.raises(ValueError, match=rf"scenario kwarg n_agents must be an int >= 0 \(a count\), got "
                                         rf"{re.escape(shown)}"):
        vmas_ros.make_env("simple_spread", num_envs=1, n_agents=value)


def test_numpy_integers_are_counts():
    env = vmas_ros.make_env("simple_spread", num_envs=2, n_agents=np.int64(4))
    assert env.n_agents == 4


def test_world_size_limits_and_their_messages(monkeypatch):
    monkeypatch.delenv(ALLOW_ENV, raising=False)
    check_world_size(30_000, {"n_agents": 100})  # the largest runs measured here stay allowed
    check_world_size(1, {"n_agents": MAX_COUNT})
    check_world_size(MAX_WORLD, {})
    with pytest.raises(ValueError, match=rf"scenario kwarg n_food=10,001 is over the limit of 10,000; "
                                         rf"set {ALLOW_ENV}=1 to build it anyway"):
        check_world_size(1, {"n_agents": 3, "n_food": MAX_COUNT + 1})
    with pytest.raises(ValueError, match=r"world too large: num_envs=200,000 x \(n_agents=60 \+ n_obstacles=40\) = "
                                         r"20,000,000 entity slots, over the limit of 10,000,000"):
        check_world_size(200_000, {"n_agents": 60, "n_obstacles": 40})
    assert check_world_size(2, {"n_agents": np.int32(3), "lidar_range": 2.5}) == {"n_agents": 3}


def test_opting_in_lifts_the_limits_but_not_the_type_checks(monkeypatch):
    monkeypatch.setenv(ALLOW_ENV, "1")
    assert check_world_size(200_000, {"n_agents": 100_000}) == {"n_agents": 100_000}
    with pytest.raises(ValueError, match="must be an int"):
        check_world_size(1, {"n_agents": 1e9})


HUGE = """
    import resource, time
    resource.setrlimit(resource.RLIMIT_AS, ({cap}, {cap}))  # a missing limit must not take the machine down
    from vmas_ros import make_env  # torch is imported here, before the clock starts
    start = time.monotonic()
    try:
        make_env("simple_spread", num_envs={num_envs}, n_agents={n_agents})
    except ValueError as error:
        print(f"REFUSED after {{time.monotonic() - start:.3f}} s: {{error}}")
"""


@pytest.mark.parametrize("num_envs, n_agents, message", [
    (1, 10**9, "scenario kwarg n_agents=1,000,000,000 is over the limit of 10,000"),
    (200_000, 100, "world too large: num_envs=200,000 x (n_agents=100) = 20,000,000 entity slots"),
])
def test_a_huge_world_is_refused_at_once(monkeypatch, num_envs, n_agents, message):
    """make_env itself refuses, before the scenario allocates (in a child capped at 2 GiB of address space)."""
    monkeypatch.delenv(ALLOW_ENV, raising=False)
    cap = 2 * 1024**3  # importing torch and a small world take about 0.7 GiB here
    code = textwrap.dedent(HUGE.format(cap=cap, num_envs=num_envs, n_agents=n_agents))
    try:
        result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail(f"make_env(num_envs={num_envs}, n_agents={n_agents}) was still building after 120 s")
    assert "REFUSED" in result.stdout, result.stdout + result.stderr[-2000:]
    assert message in result.stdout
    seconds = float(result.stdout.split("after ")[1].split(" s")[0])
    assert seconds < 1.0, result.stdout
