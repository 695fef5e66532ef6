"""``check_scenario``: one call that tells a scenario's author what the scenario gets wrong.

Like Gymnasium's ``check_env``, it is a flat sequence of small named checks,
run in this order; the first that fails raises ``ScenarioCheckError`` naming
itself and what it found against what it expected:

1. ``spaces``: the env builds with ``make_env`` in every layout (continuous,
   discrete and multidiscrete actions, dict spaces), and its observation and
   action spaces are gymnasium spaces with one entry per agent, of the
   layout's kind;
2. ``reset_observations``: ``reset()``'s observations fit the observation
   space, [B, ...] with B = ``num_envs`` (as a list, and as a dict by agent name);
3. ``step_outputs``: a step with random actions, in every layout, returns
   observations that fit the space, rewards [B] floating point, dones [B]
   bool and per agent a dict of info tensors [B, ...];
4. ``device``: every tensor that reset, step and reset_at return, and every
   entity's state, is on ``device``;
5. ``finite``: observations, rewards, infos and entity states stay finite
   over ``steps`` random steps;
6. ``determinism``: two envs built with the same seed and given the same
   actions return the same values, bit for bit;
7. ``reset_at``: ``reset_at(1)`` changes env 1 and leaves every other env's
   entity states, kept per-env tensors and observations bit-identical;
8. ``batching``: envs do not leak into each other: giving env 0 other
   actions leaves envs 1.. exactly as they were with the original ones;
9. ``vmas_parity``: when ``vmas`` is importable and the scenario has a VMAS
   counterpart, VMAS's start copied into ours and both stepped in lock-step
   agree on states, observations and rewards within ``atol``. A shipped
   scenario brings what the project knows about its counterpart: the hook
   that copies its per-env draw (``vmas_states``), and its deliberate
   differences and chaotic contacts (``vmas_differences``).

A check that does not apply (VMAS not installed, a single env) is reported as
skipped, with the reason, in the returned ``CheckReport``, which is also
logged at INFO level under ``vmas_ros.testing``.
"""
from __future__ import annotations

import copy
import logging
from typing import Callable, Optional, Union

import torch

from vmas_ros.testing.checks import (
    Subject, check_batching, check_determinism, check_device, check_finite, check_reset_at,
    check_reset_observations, check_spaces, check_step_outputs, check_vmas_parity,
)
from vmas_ros.testing.report import CheckReport, CheckSkipped, ScenarioCheckError

__all__ = ["check_scenario", "CHECKS"]

_log = logging.getLogger("vmas_ros.testing")
#: make_env keywords check_scenario sets itself (each layout in turn), refused among the scenario's kwargs
_LAYOUT_KEYWORDS = ("continuous_actions", "multidiscrete_actions", "dict_spaces", "wrapper", "wrapper_kwargs",
                    "terminated_truncated")

#: the checks, in the order they run: (name, function of a ``Subject``)
CHECKS = (
    ("spaces", check_spaces),
    ("reset_observations", check_reset_observations),
    ("step_outputs", check_step_outputs),
    ("device", check_device),
    ("finite", check_finite),
    ("determinism", check_determinism),
    ("reset_at", check_reset_at),
    ("batching", check_batching),
    ("vmas_parity", check_vmas_parity),
)


# ---------------------------------------------------------------------- runner
def _subject(scenario, num_envs, steps, seed, device, vmas_name, atol, scenario_state, scenario_kwargs) -> Subject:
    from vmas_ros.scenarios import REGISTRY, load
    from vmas_ros.simulator.scenario import BaseScenario

    for name, value, low in (("num_envs", num_envs, 1), ("steps", steps, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"check_scenario: {name} must be an int >= {low}, got {value!r}")
    if not (isinstance(atol, (int, float)) and atol >= 0):
        raise ValueError(f"check_scenario: atol must be a number >= 0, got {atol!r}")
    refused = sorted(set(scenario_kwargs) & set(_LAYOUT_KEYWORDS))
    if refused:
        raise ValueError(f"check_scenario builds the env in every layout itself: do not pass {refused} "
                         f"(scenario kwargs only)")
    if isinstance(scenario, str):
        registered = scenario.removesuffix(".py")
        load(registered)  # an unknown name fails here, listing the valid ones
        new_scenario, label = (lambda: load(registered)), registered  # noqa: E731
    elif isinstance(scenario, BaseScenario):
        if getattr(scenario, "_world", None) is not None:
            raise ValueError("check_scenario needs a scenario that has not built a world yet (it builds many envs "
                             f"from copies of it); got a {type(scenario).__name__} that has one: pass a new instance")
        template = copy.deepcopy(scenario)
        registered = next((n for n, module in REGISTRY.items()
                           if type(scenario).__module__ == module and type(scenario).__name__ == "Scenario"), None)
        kind = type(scenario).__qualname__
        label = registered or (kind if kind != "Scenario" else f"{type(scenario).__module__}.{kind}")
        new_scenario = lambda: copy.deepcopy(template)  # noqa: E731
    else:
        raise TypeError(f"check_scenario: scenario must be a registered name or a BaseScenario instance, "
                        f"got {type(scenario).__name__}")
    return Subject(label, new_scenario, registered, num_envs, steps, seed, torch.device(device), vmas_name,
                   float(atol), scenario_state, dict(scenario_kwargs))


def check_scenario(
    scenario,
    *,
    num_envs: int = 4,
    steps: int = 20,
    seed: int = 0,
    device: Union[str, torch.device] = "cpu",
    vmas_name: Optional[str] = None,
    atol: float = 1e-4,
    scenario_state: Optional[Callable[[object, object], None]] = None,
    **scenario_kwargs,
) -> CheckReport:
    """Run every check of this module's list on ``scenario``; raise ``ScenarioCheckError`` at the first failure.

    ``scenario`` is a registered name or a ``BaseScenario`` instance that has
    not built a world (every env is built from a deep copy of it);
    ``scenario_kwargs`` go to its ``make_world`` (and to VMAS's). Envs have
    ``num_envs`` copies on ``device``, made with ``seed``; random rollouts
    take ``steps`` steps.

    ``vmas_name`` names the VMAS scenario to compare with (default: the
    registered name, for a registered scenario). The comparison starts ours
    from VMAS's reset: every entity's state, and every tensor VMAS's scenario
    keeps that ours keeps under the same name and shape; a scenario that
    keeps its per-env state under other names passes
    ``scenario_state(vmas_env, our_env)``, which writes VMAS's draw into ours
    instead; a registered scenario gets its shipped hook
    (``vmas_states.SCENARIO_STATES``) unless the caller passes one.
    Observations, rewards and states must agree within ``atol``.

    Returns the ``CheckReport`` (passed and skipped checks, with reasons).
    """
    subject = _subject(scenario, num_envs, steps, seed, device, vmas_name, atol, scenario_state, scenario_kwargs)
    report = CheckReport(subject.label)
    for name, check in CHECKS:
        try:
            note = check(subject)
        except CheckSkipped as skipped:
            report.skipped[name] = str(skipped)
            continue
        except Exception as error:
            report.failed = name
            _log.info("%s", report)
            detail = str(error) if isinstance(error, AssertionError) else f"{type(error).__name__}: {error}"
            raise ScenarioCheckError(name, subject.label, detail, report) from error
        report.passed.append(name)
        if note:
            report.notes[name] = note
    _log.info("%s", report)
    return report
