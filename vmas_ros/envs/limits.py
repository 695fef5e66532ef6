"""Size limits of a world, checked before it is built.

Why: a typo or a hostile parameter (``n_agents: 1e9`` in a scenario_kwargs
string, ``num_envs`` times a huge team) would otherwise make ``make_world``
allocate until the machine swaps or the process is killed, with no error. The
limits are far above any run this project measures (30,000 envs x 100 agents,
1,000 agents in one env), and ``VMAS_ROS_ALLOW_LARGE_WORLDS=1`` lifts them for
whoever really wants more.

Count kwargs are the scenario kwargs named ``n_*`` or ``num_*`` (``n_agents``,
``n_food``, ``num_landmarks``, ``n_lidar_rays``, ...): each must be an int
(not a bool, not a float such as ``1e9`` or ``4.0``), >= 0 and at most
:data:`MAX_COUNT`. The world's size is estimated as ``num_envs`` times the sum
of the count kwargs given (at least 1) and must stay within :data:`MAX_WORLD`.
"""
from __future__ import annotations

import os
from typing import Any, Dict, Mapping

__all__ = ["ALLOW_ENV", "MAX_COUNT", "MAX_WORLD", "check_world_size", "count_kwargs"]

#: the largest value of one count kwarg (agents, landmarks, rays...)
MAX_COUNT = 10_000
#: the largest num_envs x (sum of the count kwargs given)
MAX_WORLD = 10_000_000
#: environment variable that lifts both limits when set to 1
ALLOW_ENV = "VMAS_ROS_ALLOW_LARGE_WORLDS"


def _is_count_name(name: str) -> bool:
    return name.startswith(("n_", "num_"))


def count_kwargs(kwargs: Mapping[str, Any]) -> Dict[str, int]:
    """The count kwargs of ``kwargs`` as Python ints, checked to be ints >= 0 (ValueError naming the
    first bad one); a numpy integer is accepted and converted, as scenarios check ``isinstance(n, int)``."""
    counts: Dict[str, int] = {}
    for name, value in kwargs.items():
        if not isinstance(name, str) or not _is_count_name(name):
            continue
        index = getattr(value, "__index__", None)  # ints and numpy integers; not floats or strings
        if isinstance(value, bool) or index is None:
            raise ValueError(f"scenario kwarg {name} must be an int >= 0 (a count), got {value!r} "
                             f"({type(value).__name__})")
        value = int(index())
        if value < 0:
            raise ValueError(f"scenario kwarg {name} must be an int >= 0 (a count), got {value}")
        counts[name] = value
    return counts


def check_world_size(num_envs: int, kwargs: Mapping[str, Any]) -> Dict[str, int]:
    """Refuse (ValueError) count kwargs that are no counts, and worlds past the limits; returns
    the count kwargs as Python ints.

    Called with the scenario kwargs before the world is built, so nothing is
    allocated for a refused world. The limits do not apply when the environment
    variable ``VMAS_ROS_ALLOW_LARGE_WORLDS`` is ``1``; the type checks always do.
    """
    counts = count_kwargs(kwargs)
    if os.environ.get(ALLOW_ENV) == "1":
        return counts
    opt_in = f"set {ALLOW_ENV}=1 to build it anyway"
    for name, value in counts.items():
        if value > MAX_COUNT:
            raise ValueError(f"scenario kwarg {name}={value:,} is over the limit of {MAX_COUNT:,}; {opt_in}")
    size = num_envs * max(1, sum(counts.values()))
    if size > MAX_WORLD:
        given = " + ".join(f"{n}={v:,}" for n, v in counts.items()) or "1"
        raise ValueError(f"world too large: num_envs={num_envs:,} x ({given}) = {size:,} entity slots, "
                         f"over the limit of {MAX_WORLD:,}; use fewer envs or a smaller team, or {opt_in}")
    return counts
