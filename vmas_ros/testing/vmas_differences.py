"""Where comparing a shipped scenario with its VMAS 1.5.2 counterpart has to bend, and why.

``check_scenario``'s ``vmas_parity`` check reads two tables, both keyed by
registered scenario name and used only when the scenario under check is that
registered scenario:

* ``DESIGN_DIFFERENCES``: deliberate differences (stated in the scenario's
  docstring or in docs/scenarios.md) that no common start can make agree. While one is in
  effect (it may depend on the scenario's kwargs) the check is skipped, and
  the report gives the reason and, where there is one, the kwargs under which
  the two do compare.
* ``RESYNC``: chaotic worlds. Our engine takes lengths as
  ``sqrt(x * x + y * y)`` of planar components where VMAS takes
  ``vector_norm`` of ``[..., 2]`` vectors; the two differ in the last bit for
  some inputs, and stiff contacts or joints amplify a one-ulp difference past
  ``atol`` within a few steps. These are compared one step at a time from
  VMAS's state (``run_lockstep(resync=True)``), which tests the physics, not
  the rounding; the report notes it.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable, Dict, Mapping, Optional, Tuple

__all__ = ["DesignDifference", "DESIGN_DIFFERENCES", "RESYNC", "design_difference"]


@dataclass(frozen=True)
class DesignDifference:
    """A deliberate difference from VMAS, and the scenario kwargs under which it is in effect."""

    #: what differs, and how to compare anyway where a kwarg turns it off
    reason: str
    #: of the scenario's kwargs, defaults filled in: whether the difference is in effect
    applies: Callable[[Mapping[str, object]], bool]


_ANGLE_NOISE = DesignDifference(
    "with joint_angle_obs_noise VMAS adds the noise to the rod's angle in place, so it reaches the physics; "
    "here only the observation is noisy",
    lambda kwargs: bool(kwargs["joint_angle_obs_noise"]),
)

#: registered name -> its deliberate differences from VMAS 1.5.2 that parity cannot see past
DESIGN_DIFFERENCES: Dict[str, Tuple[DesignDifference, ...]] = {
    "asym_joint": (_ANGLE_NOISE,),
    "ball_trajectory": (DesignDifference(
        "VMAS re-baselines the shared shaping at every agent's reward call, so its second agent always earns 0; "
        "here both agents earn the shared reward",
        lambda kwargs: True,
    ),),
    "discovery": (DesignDifference(
        "a covered target respawns at a spot ours draws its own way (targets_respawn=True, the default); "
        "pass targets_respawn=False to compare",
        lambda kwargs: bool(kwargs["targets_respawn"]),
    ),),
    "football": (DesignDifference(
        "the scripted team (ai_red_agents=True, the default, or ai_blue_agents=True) is our own football_ai, "
        "not VMAS's AI; pass ai_red_agents=False to compare",
        lambda kwargs: bool(kwargs["ai_red_agents"] or kwargs["ai_blue_agents"]),
    ),),
    "joint_passage": (_ANGLE_NOISE,),
    "navigation": (DesignDifference(
        "dynamics='diff_drive' is ours (VMAS's navigation has holonomic agents only): differential-drive agents "
        "with a heading in the observation; the default dynamics='holonomic' compares",
        lambda kwargs: kwargs["dynamics"] != "holonomic",
    ),),
    "joint_passage_size": (
        _ANGLE_NOISE,
        DesignDifference(
            "with pos_shaping_factor other than 1 VMAS scales the first distance by its square in steps and "
            "once at reset; here once throughout",
            lambda kwargs: kwargs["pos_shaping_factor"] != 1,
        ),
        DesignDifference(
            "with collision_reward VMAS counts the walls for the last body only; here for each",
            lambda kwargs: bool(kwargs["collision_reward"]),
        ),
    ),
}

#: registered name -> why it is compared one step at a time from VMAS's state (see the module docstring)
RESYNC: Dict[str, str] = {
    "discovery": "agents bump into each other and into the targets",
    "pollock": "dozens of agents, rods and boxes in stiff contact",
    "waterfall": "a chain of jointed agents falls through boxes",
}


def design_difference(name: str, scenario_kwargs: Mapping[str, object]) -> Optional[str]:
    """Why the shipped scenario ``name`` cannot agree with VMAS's under ``scenario_kwargs``, or None.

    Each difference is judged on the kwargs with the scenario's ``DEFAULTS``
    filled in (the registered module's table of every kwarg's default).
    """
    from vmas_ros.scenarios import REGISTRY

    differences = DESIGN_DIFFERENCES.get(name, ())
    if not differences:
        return None
    kwargs = {**importlib.import_module(REGISTRY[name]).DEFAULTS, **scenario_kwargs}
    reasons = [difference.reason for difference in differences if difference.applies(kwargs)]
    return "; ".join(reasons) or None
