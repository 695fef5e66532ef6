"""Tools for checking a scenario: ``check_scenario``, and the pieces it is built from.

``check_scenario(scenario)`` runs a flat sequence of small named checks on a
scenario (a registered name or a ``BaseScenario`` instance) and raises
``ScenarioCheckError`` naming the first that fails; see
vmas_ros/testing/check_scenario.py for the list and docs/check_scenario.md for
a walk-through. ``vmas_ros.testing.parity`` compares an env with VMAS's step
by step; the project's own tests use the same functions.
``vmas_ros.testing.vmas_states`` and ``vmas_ros.testing.vmas_differences``
hold what the comparison knows about each shipped scenario's VMAS
counterpart: how to copy its per-env draw, and where it differs on purpose.
"""
from vmas_ros.testing.check_scenario import CHECKS, check_scenario
from vmas_ros.testing.report import CheckReport, ScenarioCheckError

__all__ = ["check_scenario", "CheckReport", "ScenarioCheckError", "CHECKS"]
