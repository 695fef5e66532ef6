"""The scenario registry: every task by name.

``load(name)`` imports the scenario's module on demand and returns a fresh
``Scenario`` instance; unknown names raise a ValueError listing the valid ones.
"""
from __future__ import annotations

import difflib
import importlib
from typing import Dict, List

#: name -> module path holding ``Scenario`` (and ``HeuristicPolicy``)
REGISTRY: Dict[str, str] = {
    "simple": "vmas_ros.scenarios.mpe.simple",
    "simple_adversary": "vmas_ros.scenarios.mpe.simple_adversary",
    "simple_crypto": "vmas_ros.scenarios.mpe.simple_crypto",
    "simple_push": "vmas_ros.scenarios.mpe.simple_push",
    "simple_reference": "vmas_ros.scenarios.mpe.simple_reference",
    "simple_speaker_listener": "vmas_ros.scenarios.mpe.simple_speaker_listener",
    "simple_spread": "vmas_ros.scenarios.mpe.simple_spread",
    "simple_tag": "vmas_ros.scenarios.mpe.simple_tag",
    "simple_world_comm": "vmas_ros.scenarios.mpe.simple_world_comm",
    "balance": "vmas_ros.scenarios.balance",
    "ball_passage": "vmas_ros.scenarios.ball_passage",
    "ball_trajectory": "vmas_ros.scenarios.ball_trajectory",
    "buzz_wire": "vmas_ros.scenarios.buzz_wire",
    "discovery": "vmas_ros.scenarios.discovery",
    "dispersion": "vmas_ros.scenarios.dispersion",
    "dropout": "vmas_ros.scenarios.dropout",
    "flocking": "vmas_ros.scenarios.flocking",
    "football": "vmas_ros.scenarios.football",
    "give_way": "vmas_ros.scenarios.give_way",
    "joint_passage": "vmas_ros.scenarios.joint_passage",
    "joint_passage_size": "vmas_ros.scenarios.joint_passage_size",
    "multi_give_way": "vmas_ros.scenarios.multi_give_way",
    "navigation": "vmas_ros.scenarios.navigation",
    "passage": "vmas_ros.scenarios.passage",
    "reverse_transport": "vmas_ros.scenarios.reverse_transport",
    "road_traffic": "vmas_ros.scenarios.road_traffic",
    "sampling": "vmas_ros.scenarios.sampling",
    "transport": "vmas_ros.scenarios.transport",
    "wheel": "vmas_ros.scenarios.wheel",
    "wind_flocking": "vmas_ros.scenarios.wind_flocking",
    "asym_joint": "vmas_ros.scenarios.debug.asym_joint",
    "circle_trajectory": "vmas_ros.scenarios.debug.circle_trajectory",
    "diff_drive": "vmas_ros.scenarios.debug.diff_drive",
    "drone": "vmas_ros.scenarios.debug.drone",
    "goal": "vmas_ros.scenarios.debug.goal",
    "het_mass": "vmas_ros.scenarios.debug.het_mass",
    "kinematic_bicycle": "vmas_ros.scenarios.debug.kinematic_bicycle",
    "line_trajectory": "vmas_ros.scenarios.debug.line_trajectory",
    "pollock": "vmas_ros.scenarios.debug.pollock",
    "vel_control": "vmas_ros.scenarios.debug.vel_control",
    "waterfall": "vmas_ros.scenarios.debug.waterfall",
}

#: VMAS's three lists: the MPE ports, the debug worlds (one engine feature each), and the rest
MPE_SCENARIOS = sorted(name for name, path in REGISTRY.items() if ".mpe." in path)
DEBUG_SCENARIOS = sorted(name for name, path in REGISTRY.items() if ".debug." in path)
MAIN_SCENARIOS = sorted(set(REGISTRY) - set(MPE_SCENARIOS) - set(DEBUG_SCENARIOS))


def list_scenarios() -> List[str]:
    """Every registered scenario name, sorted."""
    return sorted(REGISTRY)


def unknown_scenario(name) -> str:
    """The message for a scenario name that is not registered: the closest name, then all of them."""
    close = difflib.get_close_matches(str(name), REGISTRY, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown scenario {name!r}{hint}; valid scenarios: {', '.join(list_scenarios())}"


def _module(name: str):
    if isinstance(name, str):
        name = name.removesuffix(".py")  # VMAS accepts "simple_spread.py" too
    if not isinstance(name, str) or name not in REGISTRY:
        raise ValueError(unknown_scenario(name))
    return importlib.import_module(REGISTRY[name])


def load(name: str):
    """A new ``Scenario`` instance of the registered scenario ``name``."""
    return _module(name).Scenario()


def make_heuristic(name: str, continuous_action: bool = True, **scenario_kwargs):
    """An instance of scenario ``name``'s heuristic, given the scenario kwargs it needs.

    Some heuristics read their observation layout from the scenario's kwargs
    (e.g. simple_tag's team sizes); they get the kwargs they accept, the others none.
    """
    import inspect

    policy_class = heuristic(name)
    parameters = inspect.signature(policy_class.__init__).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        accepted = dict(scenario_kwargs)
    else:
        accepted = {k: v for k, v in scenario_kwargs.items() if k in parameters}
    return policy_class(continuous_action=continuous_action, **accepted)


def task_score(name: str):
    """Scenario ``name``'s stand-in score, for worlds whose reward is always zero; None elsewhere.

    A few debug worlds have no task, so their heuristics chase a goal stated in
    their docstrings (drive home, stay level, keep clear). Such a module defines
    ``TASK_SCORE`` (what is scored), ``task_score(env, observations) -> [B]``
    (the per-step score, higher is better) and optionally ``EVALUATE_KWARGS``
    (kwargs the score needs). Returns ``(TASK_SCORE, task_score, EVALUATE_KWARGS)``.
    """
    module = _module(name)
    if not hasattr(module, "task_score"):
        return None
    return module.TASK_SCORE, module.task_score, dict(getattr(module, "EVALUATE_KWARGS", {}))


def heuristic(name: str):
    """The ``HeuristicPolicy`` class shipped with scenario ``name``."""
    module = _module(name)
    if not hasattr(module, "HeuristicPolicy"):
        raise ValueError(f"scenario {name!r} ships no HeuristicPolicy")
    return module.HeuristicPolicy
