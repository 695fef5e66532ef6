"""``make_env``: build a vectorized environment from a scenario name or instance."""
from __future__ import annotations

import importlib
from enum import Enum
from typing import Any, Dict, Optional, Tuple, Union

from vmas_ros.envs.environment import Environment
from vmas_ros.simulator.compile_default import default_switch_step, resolve_compile
from vmas_ros.simulator import core as _engine  # noqa: F401  every env needs the engine: load it with make_env
from vmas_ros.simulator.scenario import BaseScenario

#: wrapper name -> (module, class or function taking the Environment), imported only when
#: asked for: ``import vmas_ros`` must not pull in ray, pettingzoo or torchrl
WRAPPERS: Dict[str, Tuple[str, str]] = {
    "gym": ("vmas_ros.envs.gym_env", "GymWrapper"),
    "gymnasium": ("vmas_ros.envs.gymnasium_env", "GymnasiumWrapper"),
    "gymnasium_vec": ("vmas_ros.envs.gymnasium_vec", "GymnasiumVectorizedWrapper"),
    "pettingzoo": ("vmas_ros.envs.pettingzoo_env", "PettingZooEnv"),
    "rllib": ("vmas_ros.envs.rllib_env", "wrap"),  # one env, or the batch for num_envs > 1
    "torchrl": ("vmas_ros.envs.torchrl_env", "TorchRLEnv"),
}
#: wrappers that report terminated and truncated apart, so make_env turns the flag on for them
#: ("gym" reports one done flag and refuses the Environment with it, as VMAS's does)
_SPLIT_DONE = {"gymnasium", "gymnasium_vec", "pettingzoo", "rllib"}


def wrapper_name(wrapper: Union[str, Enum]) -> str:
    """The registry key for ``wrapper``: a name in any case, or an enum member.

    Enums are read by value when it is a string (``vmas_ros.simulator.environment.Wrapper``)
    and by member name otherwise (VMAS's own ``Wrapper.GYMNASIUM``), so VMAS code
    that passes either spelling keeps working.
    """
    if isinstance(wrapper, Enum):
        wrapper = wrapper.value if isinstance(wrapper.value, str) else wrapper.name
    if not isinstance(wrapper, str):
        raise ValueError(f"wrapper must be a name or a Wrapper enum member, got {type(wrapper).__name__}")
    name = wrapper.lower()
    if name not in WRAPPERS:
        raise ValueError(f"unknown wrapper {wrapper!r} (valid: None, {', '.join(repr(w) for w in WRAPPERS)})")
    return name


def wrap(env: Environment, wrapper: Union[str, Enum], **wrapper_kwargs: Any) -> Any:
    """Put ``env`` behind the named library wrapper, importing that library only now."""
    module_name, class_name = WRAPPERS[wrapper_name(wrapper)]
    cls = getattr(importlib.import_module(module_name), class_name)
    return cls(env, **wrapper_kwargs)


def make_env(
    scenario: Union[str, BaseScenario],
    num_envs: int = 32,
    device="cpu",
    continuous_actions: bool = True,
    wrapper: Union[None, str, Enum] = None,
    max_steps: Optional[int] = None,
    seed: Optional[int] = None,
    dict_spaces: bool = False,
    multidiscrete_actions: bool = False,
    clamp_actions: bool = False,
    grad_enabled: bool = False,
    terminated_truncated: bool = False,
    wrapper_kwargs: Optional[dict] = None,
    compile_physics: Optional[bool] = None,
    **kwargs,
) -> Any:
    """Create ``num_envs`` batched copies of ``scenario`` on ``device``.

    ``scenario`` is a registered name (see ``vmas_ros.scenarios.list_scenarios()``)
    or a BaseScenario instance; extra keyword arguments go to its ``make_world``.
    ``wrapper`` (``"gym"``, ``"gymnasium"``, ``"gymnasium_vec"``, ``"pettingzoo"``,
    ``"rllib"``, ``"torchrl"`` or a ``Wrapper`` member) returns that library's env
    instead, built with ``wrapper_kwargs`` (``"rllib"`` with ``num_envs > 1`` gives the
    batched RLlib env, vmas_ros/envs/rllib_vector.py); the gymnasium, pettingzoo and rllib
    ones always get ``terminated_truncated=True`` because those APIs report the
    two apart (VMAS asks the caller to pass it), while ``"gym"`` needs it False.
    ``compile_physics`` (not in VMAS): True runs the physics step through
    ``torch.compile`` (``World.compile_physics``: compiles on the first step, for
    seconds), False runs it eagerly (bit parity with VMAS), and None, the
    default, steps eagerly and compiles once the run is long, at a step set by
    the workload alone, where a compiler for the device is present, as
    ``VMAS_ROS_COMPILE`` says (see ``vmas_ros.simulator.compile_default``).
    ``randomisation`` (not in VMAS; a keyword, as the scenario's kwargs): a
    ``Randomisation`` or its dict, the command latency, actuator lag, sensor
    noise, lidar dropout and mass and drag scales drawn per env at every reset
    (``vmas_ros.envs.randomisation``); None, the default: none.
    """
    from vmas_ros.scenarios import load

    name = None if wrapper is None else wrapper_name(wrapper)  # a bad name fails before the world is built
    if name in _SPLIT_DONE:
        terminated_truncated = True
    compiled = resolve_compile(compile_physics, num_envs)  # a bad value fails before the world is built too

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
    if compiled:
        env.world.compile_physics()
    elif compiled is None:  # the default mode: eager first, compiled once the run is long (compile_default)
        env.world.compile_physics(after_steps=default_switch_step(num_envs, len(env.world.entities)))
    if name is None:
        return env
    return wrap(env, name, **(wrapper_kwargs or {}))
