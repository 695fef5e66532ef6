"""``vmas-ros bench jaxmarl``: what it needs from the user (JaxMARL's own interpreter), and how it says so.

JaxMARL pins its own JAX and is not among the test dependencies, so the
timed runs themselves are run by hand (docs/bench/jaxmarl.md has the command).
"""
from __future__ import annotations

import sys

import pytest

from vmas_ros.bench import jaxmarl_bench as jaxmarl
from vmas_ros.bench.cli import parse_bench_args, run_bench_command


def test_without_an_interpreter_it_says_how_to_make_one(monkeypatch, capsys):
    monkeypatch.delenv("VMAS_ROS_JAXMARL_PYTHON", raising=False)
    assert run_bench_command(parse_bench_args(["jaxmarl", "--no-progress"])) == 2
    assert "--jaxmarl-python PATH" in capsys.readouterr().err


@pytest.mark.parametrize("python, fragment", [("/nonexistent/python", "does not exist"),
                                              (sys.executable, "cannot import jaxmarl")])
def test_an_interpreter_without_jaxmarl_is_refused_by_name(python, fragment):
    with pytest.raises(ValueError, match=fragment) as error:
        jaxmarl.jaxmarl_python(python)
    assert python in str(error.value)


def test_bad_counts_are_refused():
    with pytest.raises(ValueError, match="must be >= 1"):
        jaxmarl.run_jaxmarl_benchmark(sys.executable, num_envs=[0], progress=False)


def test_the_table_says_which_side_is_faster():
    row = {"num_envs": 1, "vmas_ros_ms": 0.1, "jaxmarl_ms": 0.2, "ratio": 2.0, "switch_step": 12_500, "compiled": True}
    table = jaxmarl.format_table([row, dict(row, ratio=0.5, compiled=False)])
    assert "| 1 | 0.1000 | 0.2000 | 2.00x | compiled from step 12,500 | ✓" in table
    assert "| 0.50x | eager | ✗" in table
