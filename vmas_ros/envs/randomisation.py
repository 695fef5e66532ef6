"""Training for robots whose dynamics are not the engine's: latency, lag, noise, dropout, mass and drag.

A policy trained on the exact engine has never seen a command arrive late, a
base that follows its command with a lag, a noisy odometry or a lidar ray
that returns nothing. :class:`Randomisation` says how much of each to train
with; ``make_env(..., randomisation=...)`` (and ``vmas-ros train
--randomisation JSON``) applies it. Every setting is a range ``(low, high)``, drawn
uniformly per agent and per env at every reset of that env (a single number:
that value everywhere), with the env's own random streams:

- ``command_latency`` (s): each command takes effect this long after it is
  given, rounded to the nearest whole step of the scenario's ``dt`` (halves
  round up): ``floor(latency / dt + 1/2)`` steps. Until then after a reset, the
  agent gets a zero command.
- ``actuator_lag`` (s): the time constant ``tau`` of a first-order lag
  between the (delayed) command and what the agent executes:
  ``u <- u + alpha (command - u)`` with ``alpha = 1 - exp(-dt / tau)``
  (0: none). The executed command starts from zero at a reset.
- ``position_noise``, ``velocity_noise`` (m, m/s): the standard deviation of
  Gaussian noise, drawn anew every step, on the agent's own measured
  position and velocity, added wherever its observation derives from them
  (the scenario's ``observation_layout``; a robot computes ``pos - goal``
  from its odometry too).
- ``lidar_noise`` (m): Gaussian noise on every lidar reading that sees
  something (clamped to the sensor's range); ``lidar_dropout``: the
  probability that a ray returns nothing in a step.
- ``mass_scale``, ``drag_scale``: multipliers of each agent's mass (with its
  moment of inertia) and drag, in the engine's step
  (``World.scale_dynamics``).

Off (the default), nothing here runs: the env steps exactly as without it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Tuple, Union

__all__ = ["Randomisation", "SETTINGS"]

Range = Tuple[float, float]

#: added to ``latency / dt`` before rounding down: a half rounds up even when the division lands a hair
#: below it in floating point (0.15 / 0.1 = 1.4999999999999998)
HALF_UP = 0.5 + 1e-6

#: setting -> (unit, its value when off, help)
SETTINGS: Dict[str, Tuple[str, float, str]] = {
    "command_latency": ("s", 0.0, "delay of each command, rounded to whole steps of dt"),
    "actuator_lag": ("s", 0.0, "time constant of a first-order lag on the executed command"),
    "position_noise": ("m", 0.0, "std of Gaussian noise on the observed own position"),
    "velocity_noise": ("m/s", 0.0, "std of Gaussian noise on the observed own velocity"),
    "lidar_noise": ("m", 0.0, "std of Gaussian noise on lidar readings that see something"),
    "lidar_dropout": ("probability", 0.0, "chance that a lidar ray returns nothing in a step"),
    "mass_scale": ("x", 1.0, "multiplier of each agent's mass and moment of inertia"),
    "drag_scale": ("x", 1.0, "multiplier of each agent's drag"),
}


@dataclass(frozen=True)
class Randomisation:
    """How far training envs differ from the engine's exact model; ranges drawn per agent and env at resets."""

    command_latency: Range = (0.0, 0.0)
    actuator_lag: Range = (0.0, 0.0)
    position_noise: Range = (0.0, 0.0)
    velocity_noise: Range = (0.0, 0.0)
    lidar_noise: Range = (0.0, 0.0)
    lidar_dropout: Range = (0.0, 0.0)
    mass_scale: Range = (1.0, 1.0)
    drag_scale: Range = (1.0, 1.0)

    def __post_init__(self) -> None:
        for name in SETTINGS:
            object.__setattr__(self, name, _as_range(name, getattr(self, name)))

    @classmethod
    def from_dict(cls, values: Optional[Mapping[str, Any]]) -> "Randomisation":
        """From ``{setting: number or [low, high]}`` (a config file's or JSON's form); unknown names are refused."""
        if values is None:
            return cls()
        if isinstance(values, Randomisation):
            return values
        if not isinstance(values, Mapping):
            raise ValueError(f"randomisation must be a mapping of {sorted(SETTINGS)} to ranges, "
                             f"got {type(values).__name__}")
        unknown = sorted(set(values) - set(SETTINGS))
        if unknown:
            raise ValueError(f"unknown randomisation settings {unknown}; known: {sorted(SETTINGS)}")
        return cls(**dict(values))

    def to_dict(self) -> Dict[str, list]:
        """Every setting as ``[low, high]`` (JSON-ready; :meth:`from_dict` reads it back)."""
        return {name: list(getattr(self, name)) for name in SETTINGS}

    def active(self, *names: str) -> bool:
        """Whether any of ``names`` (all settings when none are given) differs from its value when off."""
        return any(getattr(self, name) != (SETTINGS[name][1],) * 2 for name in (names or SETTINGS))

    @property
    def acts_on_commands(self) -> bool:
        return self.active("command_latency", "actuator_lag")

    @property
    def acts_on_observations(self) -> bool:
        return self.active("position_noise", "velocity_noise", "lidar_noise", "lidar_dropout")

    @property
    def acts_on_dynamics(self) -> bool:
        return self.active("mass_scale", "drag_scale")

    def latency_steps(self, latency_s: float, dt: float) -> int:
        """A latency in whole steps: the nearest multiple of ``dt``, halves up (:data:`HALF_UP`)."""
        return int(math.floor(latency_s / dt + HALF_UP))


def _as_range(name: str, value: Union[float, int, Tuple, list]) -> Range:
    """``value`` (a number, or ``[low, high]``) as a checked ``(low, high)``; a ValueError names the setting."""
    if isinstance(value, bool):
        raise ValueError(f"randomisation {name} must be a number or [low, high], got {value!r}")
    if isinstance(value, (int, float)):
        low = high = float(value)
    elif isinstance(value, (tuple, list)) and len(value) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        low, high = float(value[0]), float(value[1])
    else:
        raise ValueError(f"randomisation {name} must be a number or [low, high], got {value!r}")
    unit = SETTINGS[name][0]
    if not (math.isfinite(low) and math.isfinite(high)) or low > high:
        raise ValueError(f"randomisation {name} must be finite with low <= high, got [{low}, {high}] ({unit})")
    if low < 0 or (name == "mass_scale" and low <= 0):
        raise ValueError(f"randomisation {name} must be {'> 0' if name == 'mass_scale' else '>= 0'}, "
                         f"got [{low}, {high}] ({unit})")
    if name == "lidar_dropout" and high > 1:
        raise ValueError(f"randomisation lidar_dropout is a probability in [0, 1], got [{low}, {high}]")
    return low, high
