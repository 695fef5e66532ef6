"""Benchmarks of vmas_ros against its peers (upstream VMAS, PettingZoo MPE).

``vmas_ros.bench.timing`` holds the shared timer; ``vmas_ros.bench.mpe`` the
simple_spread comparison of the VMAS paper (Fig. 2); ``vmas_ros.bench.suite``
the performance workloads (``vmas-ros bench suite``) and
``vmas_ros.bench.heuristics`` the heuristic-against-random evaluation
(``vmas-ros evaluate``). Benchmarks measure; they are never asserted on in tests.
"""
from vmas_ros.bench.timing import (
    Case,
    Timing,
    pinned_threads,
    time_alternating,
    time_callable,
)

__all__ = ["Case", "Timing", "pinned_threads", "time_alternating", "time_callable"]
