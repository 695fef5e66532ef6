"""The scenario registry against VMAS 1.5.2's: the same names in the same three lists,
and ``make_env`` of every name gives VMAS's observation and action spaces."""
from __future__ import annotations

import pytest
import vmas

import vmas_ros
from test.scenarios import harness
from vmas_ros.scenarios import heuristic, list_scenarios

VMAS_NAMES = sorted(vmas.scenarios + vmas.debug_scenarios + vmas.mpe_scenarios)


def test_lists_are_vmas_lists():
    assert vmas_ros.scenarios == sorted(vmas.scenarios)
    assert vmas_ros.debug_scenarios == sorted(vmas.debug_scenarios)
    assert vmas_ros.mpe_scenarios == sorted(vmas.mpe_scenarios)
    assert sorted(vmas_ros.scenarios + vmas_ros.debug_scenarios + vmas_ros.mpe_scenarios) == VMAS_NAMES
    assert len(VMAS_NAMES) == 41
    # the registry holds them all (tests may register scenarios of their own beside them)
    assert set(VMAS_NAMES) <= set(list_scenarios())


@pytest.mark.parametrize("name", VMAS_NAMES)
def test_every_scenario_ships_a_heuristic(name):
    assert callable(heuristic(name)(continuous_action=True).compute_action)


@pytest.mark.parametrize("mode", ["continuous", "discrete"])
@pytest.mark.parametrize("name", VMAS_NAMES)
def test_make_env_gives_vmas_spaces(name, mode):
    options = harness.ACTION_MODES[mode]
    ours = vmas_ros.make_env(name, num_envs=2, seed=0, **options)
    up = harness.make_upstream(name, 2, **options)
    harness.assert_same_space(ours.observation_space, up.observation_space, f"{name} observation_space")
    harness.assert_same_space(ours.action_space, up.action_space, f"{name} action_space")
