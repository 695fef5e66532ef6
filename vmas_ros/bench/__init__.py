"""Benchmarks of vmas_ros against its peers (upstream VMAS, PettingZoo MPE).

``vmas_ros.bench.timing`` holds the shared timer; ``vmas_ros.bench.mpe`` the
simple_spread comparison of the VMAS paper (Fig. 2). Benchmarks measure; they
are never asserted on in tests.
"""
from vmas_ros.bench.timing import (
    Case,
    Timing,
    pinned_threads,
    time_alternating,
    time_callable,
)

__all__ = ["Case", "Timing", "pinned_threads", "time_alternating", "time_callable"]
