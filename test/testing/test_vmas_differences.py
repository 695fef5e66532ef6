"""``vmas_ros.testing.vmas_differences``: when a shipped scenario's comparison with VMAS is skipped or resynced.

A deliberate difference skips ``vmas_parity`` only while the kwargs that
cause it are in effect; with the kwargs its reason names, the comparison runs
and passes.
"""
from __future__ import annotations

import pytest

from vmas_ros.scenarios import REGISTRY
from vmas_ros.testing import check_scenario, vmas_differences
from vmas_ros.testing.vmas_differences import design_difference

CHEAP = dict(num_envs=2, steps=4)


def test_the_tables_name_shipped_scenarios_vmas_also_has():
    import vmas

    in_vmas = set(vmas.scenarios) | set(vmas.debug_scenarios) | set(vmas.mpe_scenarios)
    for table in (vmas_differences.DESIGN_DIFFERENCES, vmas_differences.RESYNC):
        assert set(table) <= set(REGISTRY) & in_vmas


def test_with_the_default_kwargs_three_scenarios_differ_by_design():
    differing = {name: design_difference(name, {}) for name in REGISTRY if design_difference(name, {})}
    assert sorted(differing) == ["ball_trajectory", "discovery", "football"]
    assert "pass targets_respawn=False to compare" in differing["discovery"]
    assert "pass ai_red_agents=False to compare" in differing["football"]


@pytest.mark.parametrize("name, kwargs, found", [
    ("football", {"ai_red_agents": False}, None),
    ("football", {"ai_red_agents": False, "ai_blue_agents": True}, "is our own football_ai"),
    ("discovery", {"targets_respawn": False}, None),
    ("asym_joint", {"observe_joint_angle": True, "joint_angle_obs_noise": 0.1}, "adds the noise to the rod's angle"),
    ("joint_passage", {"observe_joint_angle": True, "joint_angle_obs_noise": 0.1}, "only the observation is noisy"),
    ("joint_passage_size", {"pos_shaping_factor": 2.0}, "by its square"),
    ("joint_passage_size", {"collision_reward": -1.0}, "counts the walls for the last body only"),
    ("joint_passage_size", {"pos_shaping_factor": 1}, None),
    ("simple_spread", {"n_agents": 2}, None),
    ("navigation", {"dynamics": "diff_drive"}, "VMAS's navigation has holonomic agents only"),
    ("navigation", {"dynamics": "holonomic", "n_agents": 2}, None),
])
def test_a_difference_applies_only_under_the_kwargs_that_cause_it(name, kwargs, found):
    reason = design_difference(name, kwargs)
    assert reason is None if found is None else found in reason


def test_a_difference_turned_off_by_its_kwarg_compares_and_passes():
    """discovery without respawns: no difference left, and its agents' bumping is compared step by step."""
    report = check_scenario("discovery", targets_respawn=False, **CHEAP)
    assert "vmas_parity" in report.passed and report.skipped == {}
    assert report.notes["vmas_parity"].startswith("compared one step at a time from VMAS's state")


def test_a_difference_in_effect_skips_parity_with_the_reason():
    """The skip is judged on the kwargs given: football with a scripted blue team is skipped again."""
    report = check_scenario("football", ai_red_agents=False, ai_blue_agents=True, **CHEAP)
    assert "vmas_parity" not in report.passed
    assert report.skipped["vmas_parity"].startswith("football differs from VMAS 1.5.2 by design: the scripted team")
