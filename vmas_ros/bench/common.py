"""Names shared by the MPE benchmark (:mod:`vmas_ros.bench.mpe`) and its report
(:mod:`vmas_ros.bench.report`): the scenario, the sides, their labels and the
CSV columns. Re-exported by :mod:`vmas_ros.bench.mpe`. ``BENCHMARKS`` also names
the suite (:mod:`vmas_ros.bench.suite`) and the node benchmark (:mod:`vmas_ros.bench.node`).
"""
from __future__ import annotations

SCENARIO = "simple_spread"
N_AGENTS = 3
SIDES = ("vmas_ros", "vmas", "mpe")
PEERS = ("vmas", "mpe")
_PEER_MODULE = {"vmas": "vmas", "mpe": "mpe2"}
_PEER_INSTALL = {"vmas": "pip install vmas==1.5.2", "mpe": "pip install mpe2"}
_LABEL = {"vmas_ros": "vmas_ros", "vmas": "VMAS", "mpe": "MPE"}
BENCHMARKS = ("mpe", "suite", "node")

CSV_COLUMNS = [
    "run_id", "scenario", "side", "device", "num_envs", "steps", "repeats", "median_s", "min_s", "max_s",
    "per_step_ms", "env_steps_per_s", "extrapolated", "measured_envs", "measured_in_round", "threads",
    "times_s", "peak_rss_mb", "torch_peak_mb", "loadavg_1m",
]
