"""``make_env``: build a vectorized environment from a scenario name or instance."""
from __future__ import annotations

from typing import Optional, Union

from vmas_ros.envs.environment import Environment
from vmas_ros.simulator.scenario import BaseScenario

def make_env(
    scenario: Union[str, BaseScenario],
    num_envs: int = 32,
    device="cpu",
    continuous_actions: bool = True,
    wrapper=None,
    max_steps: Optional[int] = None,
    seed: Optional[int] = None,
    dict_spaces: bool = False,
    multidiscrete_actions: bool = False,
    clamp_actions: bool = False,
    grad_enabled: bool = False,
    terminated_truncated: bool = False,
    wrapper_kwargs: Optional[dict] = None,
    **kwargs,
) -> Environment:
    """Create ``num_envs`` batched copies of ``scenario`` on ``device``.

    ``scenario`` is a registered name (see ``vmas_ros.scenarios.list_scenarios()``)
    or a BaseScenario instance; extra keyword arguments go to its ``make_world``.
    """
    from vmas_ros.scenarios import load

    if isinstance(scenario, str):
        scenario = load(scenario)
    elif isinstance(scenario, type) and issubclass(scenario, BaseScenario):
        scenario = scenario()
    if not isinstance(scenario, BaseScenario):
        raise TypeError(f"scenario must be a name or a BaseScenario instance, got {type(scenario).__name__}")
    env = Environment(
        scenario,
        num_envs=num_envs,
        device=device,
        continuous_actions=continuous_actions,
        max_steps=max_steps,
        seed=seed,
        dict_spaces=dict_spaces,
        multidiscrete_actions=multidiscrete_actions,
        clamp_actions=clamp_actions,
        grad_enabled=grad_enabled,
        terminated_truncated=terminated_truncated,
        **kwargs,
    )
    if wrapper is None:
        return env
    raise ValueError(
        f"unknown wrapper {wrapper!r}; wrappers for gymnasium, pettingzoo, torchrl and rllib are "
        f"not available in this version (valid: None)"
    )
