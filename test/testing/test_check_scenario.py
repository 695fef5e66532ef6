"""``vmas_ros.testing.check_scenario``: passes on every shipped scenario, and each check fails, naming itself.

Every broken scenario below is a real one (MPE ``simple``) with one mistake a
porting author could make; the check meant to catch it must be the one that
fails, after every check before it passed.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from vmas_ros.scenarios import REGISTRY
from vmas_ros.scenarios import navigation
from vmas_ros.scenarios.mpe import simple
from vmas_ros.testing import CHECKS, CheckReport, ScenarioCheckError, check_scenario, vmas_states

NAMES = [name for name, _ in CHECKS]
#: small and quick: enough envs to tell them apart, enough steps to move
QUICK = dict(num_envs=3, steps=8)
#: cheaper still, for the run over every shipped scenario
CHEAP = dict(num_envs=2, steps=4)
#: shipped scenarios whose comparison with VMAS is skipped with the default kwargs: a deliberate difference each
#: (vmas_ros/testing/vmas_differences.py), named by a phrase of the reason the report gives
DIFFER_BY_DESIGN = {
    "ball_trajectory": "its second agent always earns 0",
    "discovery": "pass targets_respawn=False to compare",
    "football": "pass ai_red_agents=False to compare",
}


def _vmas_names() -> set:
    import vmas

    return set(vmas.scenarios) | set(vmas.debug_scenarios) | set(vmas.mpe_scenarios)


# ------------------------------------------------------------------ passing
#: the scenarios the package ships (tests may register their own into REGISTRY, e.g. test/ros/faulty_sim.py)
SHIPPED = sorted(name for name, module in REGISTRY.items() if module.startswith("vmas_ros.scenarios."))


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_scenario_passes_with_the_defaults(name):
    """No hook, no kwargs: what a user gets from ``check_scenario(name)``, on fewer envs and steps."""
    assert name in _vmas_names()  # every registered scenario has its VMAS counterpart, so parity always applies
    report = check_scenario(name, **CHEAP)
    assert isinstance(report, CheckReport) and report.ok
    if name in DIFFER_BY_DESIGN:
        assert report.passed == NAMES[:-1] and list(report.skipped) == ["vmas_parity"]
        assert report.skipped["vmas_parity"].startswith(f"{name} differs from VMAS 1.5.2 by design: ")
        assert DIFFER_BY_DESIGN[name] in report.skipped["vmas_parity"]
    else:
        assert report.passed == NAMES and report.skipped == {}
        assert str(report).splitlines()[0] == f"check_scenario({name!r}): {len(NAMES)} passed, 0 skipped"


@pytest.mark.parametrize("name", ["balance", "simple_tag"])
def test_every_check_follows_the_device(name, device):
    report = check_scenario(name, device=device, **QUICK)
    assert report.passed == NAMES


class NavigationOfMyOwn(navigation.Scenario):
    """navigation itself, under a class no registry entry names: it gets no shipped hook."""


def test_a_scenario_keeping_state_under_its_own_names_passes_with_a_hook():
    """navigation keeps its shaping as one [B, n] tensor, VMAS on every agent: the copy by name misses it
    and says so; the hook shipped for navigation copies it."""
    with pytest.raises(ScenarioCheckError) as failure:
        check_scenario(NavigationOfMyOwn(), vmas_name="navigation", **QUICK)
    assert failure.value.check == "vmas_parity"
    assert "entity[agent_0].pos_shaping" in failure.value.detail and "scenario_state=" in failure.value.detail
    report = check_scenario(NavigationOfMyOwn(), vmas_name="navigation", scenario_state=vmas_states.navigation,
                            **QUICK)
    assert report.passed == NAMES


def test_a_callers_hook_wins_over_the_shipped_one():
    """A hook that copies nothing leaves navigation's shaping as ours drew it: the rewards differ, which
    they would not if the shipped hook had run as well."""
    calls = []
    with pytest.raises(ScenarioCheckError) as failure:
        check_scenario("navigation", scenario_state=lambda up, ours: calls.append(ours.num_envs), **QUICK)
    assert calls == [QUICK["num_envs"]]
    assert failure.value.check == "vmas_parity" and "reward of agent_0 differs" in failure.value.detail


def test_an_instance_is_checked_like_its_name_and_left_unbuilt():
    scenario = simple.Scenario()
    report = check_scenario(scenario, **QUICK)
    assert report.scenario == "simple" and report.passed == NAMES
    assert scenario._world is None  # every env was built from a copy


# ------------------------------------------------------------------ skipping
class Unregistered(simple.Scenario):
    """simple itself, under a class no registry entry names."""


def test_checks_that_do_not_apply_are_skipped_with_a_reason_never_passed():
    report = check_scenario(Unregistered(), num_envs=1, steps=4)
    assert report.ok and report.scenario == "Unregistered"
    assert set(report.skipped) == {"reset_at", "batching", "vmas_parity"}
    assert "num_envs >= 2" in report.skipped["reset_at"] and "num_envs >= 2" in report.skipped["batching"]
    assert "vmas_name=" in report.skipped["vmas_parity"]
    assert not set(report.skipped) & set(report.passed)
    assert "skipped  vmas_parity: " in str(report)


def test_noisy_observations_are_noted_where_they_limit_a_check():
    """goal's observation noise comes from the env's seeded stream, drawn as VMAS draws it: parity holds."""
    report = check_scenario("goal", obs_noise=0.1, **QUICK)
    assert report.passed == NAMES
    assert "noisy" in report.notes["reset_at"] and "only states were compared" in report.notes["reset_at"]
    assert "reset_at  (observations are noisy" in str(report)


# ------------------------------------------------------------------ failing
class ScalarObservation(simple.Scenario):
    """[B] observations: one number per env, without the feature dimension."""

    def observation(self, agent):
        return super().observation(agent)[:, 0]


class TupleObservation(simple.Scenario):
    def observation(self, agent):
        return tuple(super().observation(agent).unbind(-1))


class OneEnvObservation(simple.Scenario):
    def observation(self, agent):
        return super().observation(agent)[:1]


class GrowingObservation(simple.Scenario):
    """One more observation column once the first step has run."""

    stepped = False

    def pre_step(self):
        self.stepped = True

    def observation(self, agent):
        obs = super().observation(agent)
        return torch.cat([obs, obs[:, :1]], dim=-1) if self.stepped else obs


class InfoOnAnotherDevice(simple.Scenario):
    """An info tensor on the meta device: a device other than the env's on any machine."""

    def info(self, agent):
        return {"probe": torch.zeros(self.world.batch_dim, device="meta")}


class NaNReward(simple.Scenario):
    def reward(self, agent):
        return super().reward(agent) * float("nan")


class UnseededNoise(simple.Scenario):
    """Noise from a numpy generator of its own, seeded from the OS: not the env's streams."""

    def make_world(self, batch_dim, device, **kwargs):
        self.rng = np.random.default_rng()
        return super().make_world(batch_dim, device, **kwargs)

    def reward(self, agent):
        return super().reward(agent) + float(self.rng.normal()) * 0.01


class ResetsEveryEnv(simple.Scenario):
    def reset_world_at(self, env_index=None):
        super().reset_world_at(None)


class LeakyReward(simple.Scenario):
    """Each env's reward reads the batch's mean position: env 0's moves reach env 1's reward."""

    def reward(self, agent):
        return super().reward(agent) + agent.state.pos[:, 0].mean()


class OffsetReward(simple.Scenario):
    def reward(self, agent):
        return super().reward(agent) + 0.01


@pytest.mark.parametrize("broken, check, found", [
    (ScalarObservation, "spaces", "observation space of agent_0 (continuous layout) has shape (): "
                                  "observation() must return [B, n], not [B]"),
    (TupleObservation, "spaces", "make_env with the defaults raised AttributeError"),
    (OneEnvObservation, "reset_observations",
     "observation of agent_0 after reset has shape [1, 4], its space says [3, 4]"),
    (GrowingObservation, "step_outputs",
     "observation of agent_0 after step 1 (continuous layout) has shape [3, 5], its space says [3, 4]"),
    (InfoOnAnotherDevice, "device", "info of agent_0['probe'] after a step is on meta, expected cpu"),
    (NaNReward, "finite", "reward of agent_0 after step 1 is NaN in envs [0, 1, 2]"),
    (UnseededNoise, "determinism", "reward of agent_0 after step 1 in envs [0, 1, 2]"),
    (ResetsEveryEnv, "reset_at",
     "reset_at(1) must change env 1 only, but it changed observation of agent_0 in envs [0, 2]"),
    (LeakyReward, "batching",
     "only env 0's actions were changed, yet reward of agent_0 at step 1 in envs [1, 2]"),
    (OffsetReward, "vmas_parity", "step 1: reward of agent_0 differs from VMAS's"),
], ids=lambda value: value.__name__ if isinstance(value, type) else None)
def test_each_check_fails_naming_itself(broken, check, found):
    with pytest.raises(ScenarioCheckError) as failure:
        check_scenario(broken(), vmas_name="simple", **QUICK)
    error = failure.value
    assert isinstance(error, AssertionError)
    assert error.check == check
    assert str(error).startswith(f"check {check!r} failed for scenario {broken.__name__!r}: ")
    assert found in error.detail, error.detail
    assert error.report.failed == check and error.report.passed == NAMES[:NAMES.index(check)]


# ------------------------------------------------------------------ arguments
@pytest.mark.parametrize("scenario, kwargs, message", [
    ("simple", {"num_envs": 0}, "num_envs must be an int >= 1, got 0"),
    ("simple", {"steps": 2.5}, "steps must be an int >= 1, got 2.5"),
    ("simple", {"atol": -1}, "atol must be a number >= 0"),
    ("simple", {"continuous_actions": False}, "do not pass ['continuous_actions']"),
    ("simpel", {}, "did you mean 'simple'"),
], ids=["num_envs", "steps", "atol", "layout-keyword", "unknown-name"])
def test_bad_arguments_are_refused_by_name(scenario, kwargs, message):
    with pytest.raises(ValueError) as refused:
        check_scenario(scenario, **kwargs)
    assert message in str(refused.value)


def test_a_scenario_that_built_a_world_is_refused():
    import vmas_ros

    env = vmas_ros.make_env("simple", num_envs=2)
    with pytest.raises(ValueError, match="has not built a world"):
        check_scenario(env.scenario)
    with pytest.raises(TypeError, match="got int"):
        check_scenario(3)
