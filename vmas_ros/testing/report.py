"""What ``check_scenario`` tells: a report of the checks, and the error raised by the first that fails."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

__all__ = ["CheckReport", "ScenarioCheckError", "CheckSkipped"]


@dataclass
class CheckReport:
    """Which checks ran on a scenario, which passed, which were skipped and why.

    ``check_scenario`` returns one when every check that applies passed, and
    attaches one (with ``failed`` set) to the ``ScenarioCheckError`` it raises
    otherwise. A check that does not apply (VMAS is not installed, the
    scenario has no VMAS counterpart, a single env) is listed in ``skipped``
    with the reason, never among the passed ones.
    """

    #: the scenario's registered name, or its class name
    scenario: str
    #: the checks that passed, in the order they ran
    passed: List[str] = field(default_factory=list)
    #: check name -> why it did not apply
    skipped: Dict[str, str] = field(default_factory=dict)
    #: the check that failed (the run stops there), or None
    failed: Optional[str] = None
    #: check name -> what a passing check could not look at, or found worth knowing
    notes: Dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """No check failed (skipped ones may remain: see ``skipped``)."""
        return self.failed is None

    def __str__(self) -> str:
        lines = [f"check_scenario({self.scenario!r}): {len(self.passed)} passed, {len(self.skipped)} skipped"
                 + (f", failed at {self.failed!r}" if self.failed else "")]
        for name in self.passed:
            lines.append(f"  passed   {name}" + (f"  ({self.notes[name]})" if name in self.notes else ""))
        lines += [f"  skipped  {name}: {reason}" for name, reason in self.skipped.items()]
        if self.failed:
            lines.append(f"  FAILED   {self.failed}")
        return "\n".join(lines)


class ScenarioCheckError(AssertionError):
    """A scenario failed one of ``check_scenario``'s checks.

    ``check`` names the check, ``detail`` says what was found against what
    was expected, and ``report`` lists the checks that passed before it.
    """

    def __init__(self, check: str, scenario: str, detail: str, report: CheckReport) -> None:
        super().__init__(f"check {check!r} failed for scenario {scenario!r}: {detail}")
        self.check = check
        self.detail = detail
        self.report = report


class CheckSkipped(Exception):
    """Raised by a check that does not apply to this scenario or this machine; its message says why."""
